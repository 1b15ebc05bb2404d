"""The tracks a league board may exist for: drem's track set (the DeepRacer routes and drem's own tracks that
drem_sim ships) and the tracks staff register. A submission for any other name is refused, so an invented
`Nowhere_track` never creates a board.

The league runs where the simulator is not installed (the Lambda bundle), so drem's set is written here as the
centre-line length of each closed track, in metres, as `drem_sim.tracks.load_track(name).length` computes it
(tests/unit/test_league_tracks.py fails when the two drift apart). The names are DeepRacer's own world names
(`WORLD_NAME` in the simulation logs), which is what an export's evidence is compared with.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

from pydantic import BaseModel, ConfigDict, Field

# Generated from drem_sim.tracks (closed tracks only: an open strip has no lap).
DREM_TRACK_LENGTHS_M: Mapping[str, float] = {
    "2022_march_pro": 76.76,
    "2022_october_pro": 62.076,
    "2022_summit_speedway": 25.173,
    "2024_reinvent_champ_ccw": 25.107,
    "AWS_track": 69.254,
    "Austin": 59.351,
    "Singapore": 60.475,
    "Spain_track": 59.998,
    "arctic_pro": 59.517,
    "caecer_gp": 73.159,
    "drem_chicane": 16.261,
    "drem_oval": 17.421,
    "dubai_pro": 64.952,
    "hamption_pro": 60.742,
    "jyllandsringen_pro": 62.026,
    "morgan_pro": 59.267,
    "reInvent2019_track": 23.118,
    "reInvent2019_wide": 16.635,
    "reInvent2019_wide_ccw": 16.598,
    "reInvent2019_wide_cw": 16.598,
    "red_star_pro": 68.902,
    "reinvent_base": 17.709,
    "thunder_hill_pro": 59.148,
}


class RegisteredTrack(BaseModel):
    """A track staff added for their league (a venue's own layout, a newer DeepRacer route)."""
    model_config = ConfigDict(extra="forbid", frozen=True)
    length_m: float = Field(gt=1.0, le=500.0, allow_inf_nan=False, description="centre-line length in metres")


class RegisteredTracks(Protocol):
    def registered_tracks(self) -> dict[str, RegisteredTrack]: ...


class TrackSet:
    """Which tracks exist, and how long each one is."""

    def __init__(self, registered: RegisteredTracks | None = None,
                 builtin: Mapping[str, float] = DREM_TRACK_LENGTHS_M) -> None:
        self._registered = registered
        self._builtin = builtin

    def length_m(self, track: str) -> float | None:
        if track in self._builtin:
            return self._builtin[track]
        registered = self._registered.registered_tracks() if self._registered is not None else {}
        return registered[track].length_m if track in registered else None

    def names(self) -> list[str]:
        registered = self._registered.registered_tracks() if self._registered is not None else {}
        return sorted({*self._builtin, *registered})
