"""The tracks a booth visitor can drive: the canonical track configs the simulator ships (`drem_sim.tracks`).

The simulator is an optional part of a deployment (the Lambda bundle does not carry it): without it the catalogue
answers 503 with that reason, never a 500. Open routes (a straight test strip) are left out: `RaceEnv` refuses them.
"""
from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from typing import Any

from pydantic import BaseModel, ConfigDict

from chalicelib.core.errors import NotFound, ServiceUnavailable

TRACK_ID_PATTERN = r"^[A-Za-z0-9_.-]{1,64}$"
_OUTLINE_POINTS = 120  # enough for a recognisable map in a list, small enough for a JSON answer


class TrackInfo(BaseModel):
    model_config = ConfigDict(frozen=True)
    track_id: str
    name: str
    length_m: float
    width_m: float
    direction: str
    waypoints: int


class TrackDetail(TrackInfo):
    centerline: list[tuple[float, float]]  # metres, racing order, thinned to ~120 points


def _simulator() -> Any:
    try:
        from drem_sim import tracks
    except ModuleNotFoundError:
        raise ServiceUnavailable("The simulator (drem_sim) is not installed on this server, so it has no tracks.") \
            from None
    return tracks


@lru_cache(maxsize=1)
def _catalogue() -> dict[str, TrackDetail]:
    tracks = _simulator()
    found: dict[str, TrackDetail] = {}
    for name in sorted(tracks.available_tracks()):
        try:
            track = tracks.load_track(name)
        except Exception:  # noqa: BLE001 - a damaged track file is left out, the others still listed
            continue
        if not track.is_closed:
            continue
        step = max(1, len(track.centerline) // _OUTLINE_POINTS)
        found[name] = TrackDetail(track_id=name, name=track.name, length_m=round(track.length, 2),
                                  width_m=round(track.width, 3), direction=track.direction,
                                  waypoints=track.n_waypoints,
                                  centerline=[(round(float(x), 3), round(float(y), 3))
                                              for x, y in track.centerline[::step]])
    return found


class TrackService:
    def __init__(self, catalogue: Callable[[], dict[str, TrackDetail]] = _catalogue) -> None:
        self._catalogue = catalogue

    def all_tracks(self) -> list[TrackInfo]:
        return [TrackInfo(**t.model_dump(exclude={"centerline"})) for t in self._catalogue().values()]

    def get(self, track_id: str) -> TrackDetail:
        found = self._catalogue().get(track_id)
        if found is None:
            raise NotFound(f"There is no track {track_id[:64]!r}; GET /api/tracks lists them.", field="track_id")
        return found

    def require(self, track_id: str) -> str:
        return self.get(track_id).track_id
