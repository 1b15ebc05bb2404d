"""drem's track set for the league is the simulator's own: every closed track drem_sim ships, at the length it
computes (so a track added to drem_sim, or a route file changed, fails here until the league's table follows)."""
from __future__ import annotations

import pytest

from chalicelib.domain.league_tracks import DREM_TRACK_LENGTHS_M, RegisteredTrack, TrackSet

pytestmark = pytest.mark.unit


def test_the_league_knows_every_closed_track_drem_sim_ships_at_its_length() -> None:
    from drem_sim.tracks import available_tracks, load_track

    shipped = {name: round(track.length, 3) for name in available_tracks()
               if (track := load_track(name)).is_closed}
    assert dict(DREM_TRACK_LENGTHS_M) == shipped
    assert len(shipped) >= 22


class _Registered:
    def registered_tracks(self) -> dict[str, RegisteredTrack]:
        return {"venue_figure8": RegisteredTrack(length_m=21.5)}


def test_staff_registered_tracks_join_drems_set_and_invented_ones_do_not() -> None:
    tracks = TrackSet(_Registered())
    assert tracks.length_m("reinvent_base") == 17.709
    assert tracks.length_m("venue_figure8") == 21.5
    assert tracks.length_m("Nowhere_track") is None
    assert "venue_figure8" in tracks.names() and "Nowhere_track" not in tracks.names()
