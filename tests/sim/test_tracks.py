"""Every shipped track loads and races in both directions; an open route is refused for racing."""
from __future__ import annotations

import pytest

from drem_sim.env import RaceEnv
from drem_sim.tracks import TrackError, available_tracks, load_track

pytestmark = pytest.mark.sim

SHIPPED = sorted(available_tracks())


def test_all_shipped_npy_routes_are_found(tracks_dir) -> None:
    npy_names = {path.stem for path in tracks_dir.glob("*.npy")}
    assert npy_names and npy_names <= set(SHIPPED)
    assert {"drem_oval", "drem_chicane"} <= set(SHIPPED)


@pytest.mark.parametrize("name", SHIPPED)
@pytest.mark.parametrize("reverse", [False, True])
def test_track_loads_in_both_directions(name: str, reverse: bool) -> None:
    track = load_track(name, reverse=reverse)
    assert track.length > 4.0
    assert 0.5 < track.width < 1.2
    assert track.is_reversed == reverse
    if track.is_closed:
        forward = load_track(name)
        assert track.length == pytest.approx(forward.length)
        assert track.direction != forward.direction or not reverse


def test_known_track_facts() -> None:
    base = load_track("reinvent_base")
    assert base.length == pytest.approx(17.71, abs=0.05)
    assert base.width == pytest.approx(0.762, abs=0.01)
    assert base.direction == "CCW"
    assert load_track("reinvent_base", reverse=True).direction == "CW"


def test_open_route_is_refused_for_racing_with_a_clear_error() -> None:
    straight = load_track("Straight_track")
    assert not straight.is_closed
    with pytest.raises(TrackError, match="open route"):
        RaceEnv(straight)


def test_unknown_track_names_the_known_ones() -> None:
    with pytest.raises(TrackError, match="reinvent_base"):
        load_track("no_such_track")


def test_malformed_yaml_track_is_rejected(tmp_path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("track_id: bad\ncenterline: [[0, 0], [1, 0], [1, 1]]\n")  # neither width nor borders
    with pytest.raises(TrackError, match="width"):
        load_track(bad)
