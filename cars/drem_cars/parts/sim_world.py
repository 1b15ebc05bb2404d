"""The simulated car for `drem car run --sim`: the simulator's own `drem_sim.env.RaceEnv`, on a simulated clock.

The car drives the very environment models are trained and evaluated in (same physics, track friction, camera and
virtual timing strip), so a sample model behaves in a car as it did in `drem sim`. The world advances one camera frame
(1/15 s of sim time) per drive-loop tick, so a loop run faster than 15 Hz simply runs the race faster than real time
and timestamps stay exact. The timing line is the simulator's `TimingLine` (the track's `timing_line`, or the line
across waypoint 0, with the hardware's 2 s debounce): each forward crossing of the car's front point becomes a strip
crossing at `epoch_ms + sim time`, interpolated inside the physics step. Leaving the track puts the car back on the
centre line at rest, as DeepRacer's reset does; the teleport never counts as a crossing.
"""
from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from drem_sim.env import EnvConfig, RaceEnv
from drem_sim.timing import TimingConfig
from drem_sim.tracks import load_track

FRAME_PERIOD_S = 1.0 / 15.0
START_BEHIND_LINE_M = 1.0  # the car starts this far before the timing line: its first crossing starts the race


class SimWorld:
    def __init__(self, track_name: str, *, start_epoch_ms: int | None = None, device_id: str = "sim",
                 seed: int | None = None) -> None:
        self.start_epoch_ms = int(time.time() * 1000) if start_epoch_ms is None else start_epoch_ms
        timing = TimingConfig(device_id=device_id, epoch_ms=self.start_epoch_ms)
        track = load_track(track_name).require_racing_loop()
        start = track.length - START_BEHIND_LINE_M
        self.env = RaceEnv(track, EnvConfig(decision_hz=1.0 / FRAME_PERIOD_S, start_offset_m=start,
                                                  timing=timing))
        self.track = self.env.track
        self._frame, _info = self.env.reset(seed=seed)
        self._action = (0.0, 0.0)
        self.crossings: list[tuple[int, int]] = []  # (timestamp_ms, sensor), drained by the camera part
        self._lock = threading.Lock()

    @property
    def resets(self) -> int:
        return self.env.resets

    @property
    def params(self) -> dict[str, Any]:
        """DeepRacer's params of the current state (what the stand-in driver steers by)."""
        return self.env.params

    def pose(self) -> tuple[float, float, float]:
        state = self.env.car_state()
        return state["x"], state["y"], state["heading"]

    def render(self) -> np.ndarray:
        """The camera frame of the current pose (rendered by the environment when it stepped)."""
        assert self._frame is not None, "the sim car's environment has a camera"
        return self._frame

    def command(self, steering_deg: float, speed_mps: float) -> None:
        self._action = (steering_deg, speed_mps)

    def advance(self) -> None:
        """One frame period of physics; records timing-line crossings (resets happen inside the environment)."""
        self._frame, _params, _terminated, _truncated, info = self.env.step(self._action)
        if info["strip_events"]:
            with self._lock:
                self.crossings.extend((e["timestamp_ms"], e["sensor"]) for e in info["strip_events"])

    def drain_crossings(self) -> list[tuple[int, int]]:
        with self._lock:
            crossings, self.crossings = self.crossings, []
        return crossings
