"""Race tracks: DeepRacer `.npy` route files and drem's own YAML tracks.

A `Track` holds the centre line and both borders as numpy arrays in metres, in racing order.
Closed tracks store each waypoint once (the repeated closing row of a `.npy` file is dropped);
segment i runs from waypoint i to waypoint i+1 (wrapping on a closed track).
"inner"/"outer" are the geometric inside/outside borders, whatever the racing direction,
as in the DeepRacer files; "left"/"right" are relative to the racing direction.
"""
from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

# drem's own YAML tracks and the real DeepRacer route files (deepracer-simapp, Apache-2.0; see tracks/NOTICE.md) ship
# inside the package: an organiser's laptop has nothing else to read them from.
PACKAGE_TRACKS_DIR = Path(__file__).resolve().parent / "tracks"
TRACKS_DIR_ENV = "DREM_TRACKS_DIR"
# A folder's `SHA256SUMS` (sha256sum's format): a listed route file whose bytes differ is refused, never driven.
CHECKSUMS_FILE = "SHA256SUMS"


class TrackError(ValueError):
    """A track file is malformed, not found, or unfit for the requested use."""


class SimParams(BaseModel):
    """Per-track simulator settings (all optional)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    camera_width: int = Field(160, ge=16, le=1280)
    camera_height: int = Field(120, ge=16, le=960)
    camera_hfov_rad: float = Field(1.13, gt=0.1, lt=3.0)
    friction: float = Field(1.0, gt=0.05, le=3.0)


class Pose(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    x: float
    y: float
    heading_deg: float


class Zone(BaseModel):
    """A named stretch of the lap for evaluation, in percent of progress."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str
    from_progress: float = Field(ge=0, le=100)
    to_progress: float = Field(ge=0, le=100)


Point = tuple[float, float]


class TrackSpec(BaseModel):
    """The YAML track format (see docs/sim.md)."""

    model_config = ConfigDict(extra="forbid")
    track_id: str = Field(pattern=r"^[A-Za-z0-9_.-]{1,64}$")
    name: str = ""
    closed: bool = True
    centerline: list[Point] = Field(min_length=3)
    width: float | None = Field(None, gt=0.1, le=5.0)
    inner: list[Point] | None = None
    outer: list[Point] | None = None
    spawn: Pose | None = None
    timing_line: tuple[Point, Point] | None = None
    zones: list[Zone] = []
    sim: SimParams = SimParams()

    @model_validator(mode="after")
    def _one_way_to_give_borders(self) -> TrackSpec:
        has_borders = self.inner is not None or self.outer is not None
        if has_borders == (self.width is not None):
            raise ValueError("give either `width` or both `inner` and `outer` borders")
        if has_borders:
            if self.inner is None or self.outer is None:
                raise ValueError("`inner` and `outer` must be given together")
            if not len(self.inner) == len(self.outer) == len(self.centerline):
                raise ValueError("`centerline`, `inner` and `outer` need the same number of points")
        return self


@dataclass(frozen=True, eq=False)
class Projection:
    """Where points fall on the centre line (arrays, one entry per point)."""

    segment: np.ndarray  # index of the closest segment
    along: np.ndarray  # fraction 0..1 inside that segment
    s: np.ndarray  # arc length from waypoint 0, metres
    offset: np.ndarray  # signed distance from the centre line, + = left of the racing direction
    half_width: np.ndarray  # half the track width at that spot

    @property
    def distance(self) -> np.ndarray:
        return np.abs(self.offset)

    @property
    def on_track(self) -> np.ndarray:
        return np.abs(self.offset) <= self.half_width


@dataclass(frozen=True, eq=False)
class Track:
    track_id: str
    name: str
    centerline: np.ndarray  # (N, 2)
    inner: np.ndarray  # (N, 2)
    outer: np.ndarray  # (N, 2)
    is_closed: bool
    source: str = ""
    spawn: Pose | None = None
    timing_line: tuple[Point, Point] | None = None
    zones: tuple[Zone, ...] = ()
    sim: SimParams = field(default_factory=SimParams)
    is_reversed: bool = False

    def __post_init__(self) -> None:
        for name in ("centerline", "inner", "outer"):
            arr = np.ascontiguousarray(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if len(self.centerline) < 3:
            raise TrackError(f"track {self.track_id!r}: needs at least 3 distinct waypoints")

    # ---- geometry -------------------------------------------------------------------------
    @cached_property
    def _segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        a = self.centerline
        b = np.roll(a, -1, axis=0) if self.is_closed else a[1:]
        a = a if self.is_closed else a[:-1]
        d = b - a
        lengths = np.hypot(d[:, 0], d[:, 1])
        return a, d, lengths, d / lengths[:, None]

    @cached_property
    def widths(self) -> np.ndarray:
        """Track width at each waypoint (distance between the inner and outer points)."""
        return np.hypot(*(self.outer - self.inner).T)

    @cached_property
    def cumulative(self) -> np.ndarray:
        """Arc length at each waypoint, plus the full length as the last entry on a closed track."""
        return np.concatenate([[0.0], np.cumsum(self._segments[2])])

    @property
    def length(self) -> float:
        return float(self.cumulative[-1])

    @property
    def width(self) -> float:
        return float(np.median(self.widths))

    @cached_property
    def signed_area(self) -> float:
        x, y = self.centerline.T
        return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))

    @property
    def direction(self) -> Literal["CCW", "CW", "open"]:
        if not self.is_closed:
            return "open"
        return "CCW" if self.signed_area > 0 else "CW"

    @property
    def n_waypoints(self) -> int:
        return len(self.centerline)

    @cached_property
    def waypoints(self) -> list[tuple[float, float]]:
        """Centre-line points as a list of tuples (the DeepRacer `waypoints` param; shared, do not mutate)."""
        return [(float(x), float(y)) for x, y in self.centerline]

    @cached_property
    def bounds(self) -> tuple[float, float, float, float]:
        pts = np.vstack([self.inner, self.outer, self.centerline])
        return float(pts[:, 0].min()), float(pts[:, 1].min()), float(pts[:, 0].max()), float(pts[:, 1].max())

    def require_racing_loop(self) -> Track:
        if not self.is_closed:
            raise TrackError(
                f"track {self.track_id!r} is an open route (its first and last waypoints differ): "
                "it can be inspected but not raced; pick a closed loop")
        return self

    # ---- projection -----------------------------------------------------------------------
    def project(self, points: Any) -> Projection:
        """Project points (shape (2,) or (P, 2)) on the centre line."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        a, d, lengths, unit = self._segments
        rel = p[:, None, :] - a[None, :, :]  # (P, S, 2)
        t = np.clip((rel * d).sum(-1) / (lengths * lengths), 0.0, 1.0)
        foot = a + t[..., None] * d
        dist2 = ((p[:, None, :] - foot) ** 2).sum(-1)
        seg = dist2.argmin(axis=1)
        rows = np.arange(len(p))
        along = t[rows, seg]
        cross = unit[seg, 0] * rel[rows, seg, 1] - unit[seg, 1] * rel[rows, seg, 0]
        dist = np.sqrt(dist2[rows, seg])
        offset = np.where(cross >= 0, dist, -dist)
        nxt = (seg + 1) % self.n_waypoints
        half = 0.5 * (self.widths[seg] * (1 - along) + self.widths[nxt] * along)
        s = self.cumulative[seg] + along * lengths[seg]
        return Projection(segment=seg, along=along, s=s, offset=offset, half_width=half)

    @cached_property
    def _segment_rows(self) -> list[tuple[float, float, float, float, float, float, float]]:
        """Per segment as plain floats: ax, ay, dx, dy, length², width at start, width at end."""
        a, d, lengths, _ = self._segments
        w = self.widths
        n = self.n_waypoints
        return [(float(a[i, 0]), float(a[i, 1]), float(d[i, 0]), float(d[i, 1]), float(lengths[i] ** 2),
                 float(w[i]), float(w[(i + 1) % n])) for i in range(len(a))]

    def locate(self, x: float, y: float, hint: int, back: int = 3, ahead: int = 6) -> tuple[int, float, float, float]:
        """Fast local projection of one point near segment `hint`: (segment, along, offset, half_width).

        Scans a few segments around the hint in plain Python (the per-step hot path of the env);
        callers re-seed the hint with `project` after a jump (a reset, a teleport).
        """
        rows = self._segment_rows
        n = len(rows)
        best = (hint, 0.0, 0.0, 0.0)
        best_d2 = math.inf
        for k in range(hint - back, hint + ahead + 1):
            if self.is_closed:
                i = k % n
            elif 0 <= k < n:
                i = k
            else:
                continue
            ax, ay, dx, dy, l2, w0, w1 = rows[i]
            rx, ry = x - ax, y - ay
            t = (rx * dx + ry * dy) / l2
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            ex, ey = rx - t * dx, ry - t * dy
            d2 = ex * ex + ey * ey
            if d2 < best_d2:
                best_d2 = d2
                dist = math.sqrt(d2)
                best = (i, t, dist if dx * ry - dy * rx >= 0 else -dist, 0.5 * (w0 + (w1 - w0) * t))
        return best

    @cached_property
    def _arc_rows(self) -> tuple[list[float], list[float]]:
        """Arc length at each waypoint and each segment's length as Python floats (indexing numpy per step costs
        more than the arithmetic)."""
        return [float(v) for v in self.cumulative], [float(v) for v in self._segments[2]]

    def arc_length(self, segment: int, along: float) -> float:
        starts, lengths = self._arc_rows
        return starts[segment] + along * lengths[segment]

    def on_track(self, points: Any) -> np.ndarray:
        return self.project(points).on_track

    def closest_waypoints(self, point: Any) -> tuple[int, int]:
        """(previous, next) waypoint indices around the point's projection, in racing order."""
        seg = int(self.project(point).segment[0])
        return seg, (seg + 1) % self.n_waypoints

    def progress(self, point: Any) -> float:
        """Percent of the lap from waypoint 0 to the point's projection (0..100)."""
        return float(100.0 * self.project(point).s[0] / self.length)

    def pose_at(self, s: float) -> tuple[float, float, float]:
        """(x, y, heading in radians) on the centre line at arc length s (wrapped on a loop)."""
        if self.is_closed:
            s = s % self.length
        s = min(max(s, 0.0), self.length)
        seg = int(np.searchsorted(self.cumulative, s, side="right") - 1)
        a, d, lengths, unit = self._segments
        seg = min(max(seg, 0), len(a) - 1)
        frac = (s - self.cumulative[seg]) / lengths[seg]
        x, y = a[seg] + frac * d[seg]
        return float(x), float(y), math.atan2(unit[seg, 1], unit[seg, 0])

    def default_timing_line(self) -> tuple[Point, Point]:
        """Perpendicular to the centre line at waypoint 0, spanning the track width plus a margin."""
        x, y, heading = self.pose_at(0.0)
        half = 0.5 * self.widths[0] + 0.15
        nx, ny = -math.sin(heading), math.cos(heading)
        return (x + half * nx, y + half * ny), (x - half * nx, y - half * ny)

    def reversed(self) -> Track:
        """The same loop raced the other way; waypoint 0 (and the timing line) stay where they are."""
        order = np.r_[0, np.arange(self.n_waypoints - 1, 0, -1)] if self.is_closed else np.arange(
            self.n_waypoints - 1, -1, -1)
        spawn = None
        if self.spawn is not None:
            spawn = Pose(x=self.spawn.x, y=self.spawn.y, heading_deg=_wrap_deg(self.spawn.heading_deg + 180.0))
        zones = tuple(Zone(name=z.name, from_progress=100 - z.to_progress, to_progress=100 - z.from_progress)
                      for z in self.zones)
        return replace(self, centerline=self.centerline[order], inner=self.inner[order], outer=self.outer[order],
                       spawn=spawn, zones=zones, is_reversed=not self.is_reversed)

    def summary(self) -> dict[str, Any]:
        return {"track_id": self.track_id, "name": self.name, "length_m": round(self.length, 2),
                "width_m": round(self.width, 3), "direction": self.direction, "closed": self.is_closed,
                "waypoints": self.n_waypoints, "source": self.source}


def _wrap_deg(angle: float) -> float:
    return (angle + 180.0) % 360.0 - 180.0


def _drop_repeats(rows: np.ndarray, closed: bool) -> np.ndarray:
    """Remove consecutive duplicate centre points (some route files repeat rows) and the closing row."""
    keep = np.ones(len(rows), dtype=bool)
    keep[1:] = np.hypot(*(rows[1:, :2] - rows[:-1, :2]).T) > 1e-9
    rows = rows[keep]
    if closed and len(rows) > 1 and np.allclose(rows[0, :2], rows[-1, :2]):
        rows = rows[:-1]
    return rows


def track_from_npy(path: str | Path) -> Track:
    path = Path(path)
    name = path.stem
    _check_sum(path)
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise TrackError(f"track {name!r}: {path} is not a readable .npy route file ({exc}); restore the file or "
                         "reinstall drem") from exc
    if data.ndim != 2 or data.shape[1] != 6 or data.shape[0] < 3:
        raise TrackError(f"track {name!r}: {path} should hold rows of centre, inner and outer x,y (an N×6 array); "
                         f"it holds shape {data.shape}")
    if not np.isfinite(data).all():
        raise TrackError(f"track {name!r}: {path} contains NaN or infinite values")
    data = data.astype(np.float64)
    closed = bool(np.array_equal(data[0], data[-1]))
    rows = _drop_repeats(data, closed)
    return Track(track_id=name, name=name, centerline=rows[:, 0:2], inner=rows[:, 2:4],
                 outer=rows[:, 4:6], is_closed=closed, source=str(path))


def _check_sum(path: Path) -> None:
    """Refuse a route file that its folder's SHA256SUMS lists with other bytes (damaged on disk, or edited)."""
    expected = _listed_sums(path.parent).get(path.name)
    if expected is None:
        return
    try:
        actual = hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as exc:
        raise TrackError(f"track {path.stem!r}: cannot read {path} ({exc.strerror or exc})") from exc
    if actual != expected:
        raise TrackError(f"track {path.stem!r}: {path} does not match its checksum in {path.parent / CHECKSUMS_FILE} "
                         "(the file is damaged or was changed); restore it or reinstall drem")


def _listed_sums(folder: Path) -> dict[str, str]:
    listing = folder / CHECKSUMS_FILE
    try:
        text = listing.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return {}
    sums: dict[str, str] = {}
    for line in text.splitlines():
        digest, _, name = line.strip().partition(" ")
        if len(digest) == 64 and name:
            sums[name.strip().lstrip("*")] = digest.lower()
    return sums


def track_from_spec(spec: TrackSpec, source: str = "") -> Track:
    centre = np.asarray(spec.centerline, dtype=np.float64)
    if spec.width is not None:
        inner, outer = offset_borders(centre, spec.width, spec.closed)
    else:
        inner = np.asarray(spec.inner, dtype=np.float64)
        outer = np.asarray(spec.outer, dtype=np.float64)
    rows = np.hstack([centre, inner, outer])
    rows = _drop_repeats(rows, spec.closed)
    return Track(track_id=spec.track_id, name=spec.name or spec.track_id, centerline=rows[:, 0:2],
                 inner=rows[:, 2:4], outer=rows[:, 4:6], is_closed=spec.closed, source=source,
                 spawn=spec.spawn, timing_line=spec.timing_line, zones=tuple(spec.zones), sim=spec.sim)


def offset_borders(centre: np.ndarray, width: float, closed: bool) -> tuple[np.ndarray, np.ndarray]:
    if closed:
        tangent = np.roll(centre, -1, axis=0) - np.roll(centre, 1, axis=0)
    else:
        tangent = np.gradient(centre, axis=0)
    tangent /= np.hypot(*tangent.T)[:, None]
    left = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1) * (width / 2)
    x, y = centre.T
    area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    # On a counter-clockwise loop the left border is the inside one.
    if area >= 0:
        return centre + left, centre - left
    return centre - left, centre + left


def track_from_yaml(path: str | Path) -> Track:
    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise TrackError(f"{path}: cannot read YAML ({exc})") from exc
    if not isinstance(raw, dict):
        raise TrackError(f"{path}: a track file must be a YAML mapping")
    try:
        spec = TrackSpec.model_validate(raw)
    except ValidationError as exc:
        raise TrackError(f"{path}: invalid track: {exc}") from exc
    return track_from_spec(spec, source=str(path))


def npy_dirs() -> list[Path]:
    """Where `.npy` routes are looked up: the package's own (the 22 real DeepRacer tracks), then any folders staff add
    in $DREM_TRACKS_DIR (os.pathsep-separated). A shipped name always means the shipped file."""
    dirs = [Path(p) for p in os.environ.get(TRACKS_DIR_ENV, "").split(os.pathsep) if p]
    return [PACKAGE_TRACKS_DIR, *dirs]


def available_tracks() -> dict[str, Path]:
    """Track name -> file, YAML tracks shipped with the package first, then `.npy` routes."""
    found: dict[str, Path] = {}
    for path in sorted(PACKAGE_TRACKS_DIR.glob("*.yaml")):
        found.setdefault(path.stem, path)
    for folder in npy_dirs():
        if folder.is_dir():
            for path in sorted(folder.glob("*.npy")):
                found.setdefault(path.stem, path)
    return found


# The track a command drives when none is named: re:Invent 2018 (shipped), else drem_oval (a damaged install).
DEFAULT_TRACK_CHOICES = ("reinvent_base", "drem_oval")


def default_track_name() -> str:
    found = available_tracks()
    return next((name for name in DEFAULT_TRACK_CHOICES if name in found), DEFAULT_TRACK_CHOICES[-1])


def load_track(name_or_path: str | Path, *, reverse: bool = False) -> Track:
    """Load a track by file path, shipped YAML id, or `.npy` route name; `reverse` races it the other way."""
    path = Path(name_or_path)
    if not path.is_file() and isinstance(name_or_path, str):
        from drem_sim import generated_tracks  # drawn from its seed, never a file

        if generated_tracks.is_generated(name_or_path):
            track = generated_tracks.generated_track(name_or_path)
            return track.reversed() if reverse else track
    if not path.is_file():
        path = available_tracks().get(str(name_or_path), Path())
        if not path.is_file():
            names = ", ".join(sorted(available_tracks())) or "(none found)"
            raise TrackError(f"unknown track {str(name_or_path)!r}; known tracks: {names} "
                             f"(staff can add a folder of .npy route files with {TRACKS_DIR_ENV})")
    if path.suffix == ".npy":
        track = track_from_npy(path)
    elif path.suffix in (".yaml", ".yml"):
        track = track_from_yaml(path)
    else:
        raise TrackError(f"track {path.stem!r}: {path} is no track file (want .npy or .yaml)")
    return track.reversed() if reverse else track
