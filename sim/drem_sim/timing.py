"""A virtual timing strip: the simulated twin of the pressure strips taped across the start line.

The car's front point moves in a straight segment between two physics steps; when that segment
crosses the timing line in the racing direction, the crossing instant is interpolated inside the
step (not rounded to the step) and reported exactly like the hardware timer reports a strip press:
`{"timestamp_ms", "sensor", "idempotency_key"}`. Like the hardware, one sensor ignores presses for
`debounce_ms` after a press. A car put back on the track is teleported, not driven: call `jump()`
so the teleport never counts as a crossing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from drem_sim.tracks import Point, Track

STRIP_SENSOR = 17  # the first timing-strip GPIO (BCM 17) of the DREM leaderboard timer
HARDWARE_DEBOUNCE_MS = 2000
ON_LINE_TOLERANCE = 1e-9  # m² (line length x distance): closer than this counts as on the line


@dataclass(frozen=True)
class TimingConfig:
    device_id: str = "sim-timer"
    sensor: int = STRIP_SENSOR
    epoch_ms: int = 0  # wall-clock ms that sim time 0 maps to
    debounce_ms: int = HARDWARE_DEBOUNCE_MS


def strip_event(timestamp_ms: int, sensor: int, device_id: str, seq: int) -> dict[str, Any]:
    return {"timestamp_ms": int(timestamp_ms), "sensor": int(sensor), "idempotency_key": f"{device_id}-{seq}"}


class TimingLine:
    """Detects forward crossings of a line segment `(a, b)` by a moving point."""

    def __init__(self, line: tuple[Point, Point], forward: tuple[float, float],
                 config: TimingConfig | None = None) -> None:
        self.config = config or TimingConfig()
        (ax, ay), (bx, by) = line
        self._a = (float(ax), float(ay))
        self._d = (float(bx) - ax, float(by) - ay)
        if self._d[0] == 0.0 and self._d[1] == 0.0:
            raise ValueError("a timing line needs two distinct end points")
        # Which side of the line the racing direction points to (sign of line × forward).
        side = self._d[0] * forward[1] - self._d[1] * forward[0]
        if side == 0.0:
            raise ValueError("the racing direction runs along the timing line, not across it")
        self._forward_sign = 1.0 if side > 0 else -1.0
        self.seq = 0
        self._last_ms: int | None = None
        self._prev: tuple[float, float, float] | None = None  # (t_s, x, y)

    @classmethod
    def for_track(cls, track: Track, config: TimingConfig | None = None) -> TimingLine:
        """The track's own timing line (YAML `timing_line`) or the default one across waypoint 0."""
        line = track.timing_line or track.default_timing_line()
        (ax, ay), (bx, by) = line
        mid = ((ax + bx) / 2, (ay + by) / 2)
        seg = int(track.project(mid).segment[0])
        _, _, heading = track.pose_at(track.arc_length(seg, 0.5))
        return cls(line, (math.cos(heading), math.sin(heading)), config)

    @property
    def points(self) -> tuple[Point, Point]:
        return self._a, (self._a[0] + self._d[0], self._a[1] + self._d[1])

    def jump(self, t_s: float, x: float, y: float) -> None:
        """The point was placed here (start, reset): no crossing is reported for the move."""
        self._prev = (t_s, x, y)

    def observe(self, t_s: float, x: float, y: float) -> dict[str, Any] | None:
        """The point reached (x, y) at sim time t_s; returns a strip event if it crossed the line since the last
        call."""
        prev, self._prev = self._prev, (t_s, x, y)
        if prev is None:
            return None
        t0, x0, y0 = prev
        crossing = self._crossing_fraction(x0, y0, x, y)
        if crossing is None:
            return None
        at_ms = self.config.epoch_ms + round((t0 + crossing * (t_s - t0)) * 1000.0)
        if self._last_ms is not None and at_ms - self._last_ms < self.config.debounce_ms:
            return None
        self._last_ms = at_ms
        self.seq += 1
        return strip_event(at_ms, self.config.sensor, self.config.device_id, self.seq)

    def _crossing_fraction(self, x0: float, y0: float, x1: float, y1: float) -> float | None:
        """Fraction 0..1 of the move (x0,y0)->(x1,y1) at which it crosses the line forwards, else None."""
        ax, ay = self._a
        dx, dy = self._d
        side0 = (dx * (y0 - ay) - dy * (x0 - ax)) * self._forward_sign
        side1 = (dx * (y1 - ay) - dy * (x1 - ax)) * self._forward_sign
        # Forward = from strictly behind the line to on or ahead of it. A point placed exactly on the
        # line (a car spawned on the start line) is not behind it: float noise must not press the strip.
        if not (side0 < -ON_LINE_TOLERANCE <= 0.0 <= side1):
            return None
        fraction = side0 / (side0 - side1)
        # Where on the line's own segment the crossing lies: outside its ends is no press.
        px, py = x0 + fraction * (x1 - x0), y0 + fraction * (y1 - y0)
        along = ((px - ax) * dx + (py - ay) * dy) / (dx * dx + dy * dy)
        return fraction if 0.0 <= along <= 1.0 else None
