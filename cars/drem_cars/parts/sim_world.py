"""The simulated car for `drem car run --sim`: a drem_sim track, car physics and camera, on a simulated clock.

The world advances one camera frame period per drive-loop tick (sim time, not wall time), so a loop run faster than
15 Hz simply runs the race faster than real time and timestamps stay exact. The track's timing line (waypoint 0, as
the simulator's) is a virtual timing strip: each forward crossing of the car's front point becomes a crossing at
`epoch_ms + sim time`, interpolated inside the step. Leaving the track puts the car back on the centre line at rest,
as DeepRacer's reset does.
"""
from __future__ import annotations

import math
import threading
import time

import numpy as np

FRAME_PERIOD_S = 1.0 / 15.0
VIRTUAL_STRIP_SENSOR = 17  # reported like the first timing-strip GPIO


class SimWorld:
    def __init__(self, track_name: str, *, physics_hz: float = 60.0, start_epoch_ms: int | None = None,
                 frame_period_s: float = FRAME_PERIOD_S) -> None:
        from drem_sim.camera import Camera
        from drem_sim.physics import CarPhysics
        from drem_sim.tracks import load_track

        self.track = load_track(track_name).require_racing_loop()
        self.physics = CarPhysics(dt=1.0 / physics_hz)
        self.camera = Camera(self.track)
        self.frame_period_s = frame_period_s
        self.sim_time_s = 0.0
        self.start_epoch_ms = int(time.time() * 1000) if start_epoch_ms is None else start_epoch_ms
        self.resets = 0
        self.crossings: list[tuple[int, int]] = []  # (timestamp_ms, sensor), drained by the camera part
        self._lock = threading.Lock()
        x, y, heading = self.track.pose_at(self.track.length - 1.0)  # 1 m before the line: the first crossing starts
        self.physics.reset(x, y, heading)
        self._hint = int(self.track.project(self.physics.front_point()).segment[0])
        self._s = self._arc()

    def _arc(self) -> float:
        x, y = self.physics.front_point()
        segment, along, offset, half = self.track.locate(x, y, self._hint)
        self._hint, self._offset, self._half = segment, offset, half
        return self.track.arc_length(segment, along)

    def pose(self) -> tuple[float, float, float]:
        return self.physics.x, self.physics.y, self.physics.heading

    def render(self) -> np.ndarray:
        return self.camera.render(*self.pose())

    def command(self, steering_deg: float, speed_mps: float) -> None:
        self.physics.command(steering_deg, speed_mps)

    def advance(self) -> None:
        """One frame period of physics; records timing-line crossings and resets an off-track car."""
        steps = max(1, round(self.frame_period_s / self.physics.dt))
        length = self.track.length
        for _ in range(steps):
            before = self._s
            t_before = self.sim_time_s
            self.physics.step()
            self.sim_time_s += self.physics.dt
            after = self._arc()
            if before > 0.75 * length and after < 0.25 * length:  # forward over the line at s = 0
                fraction = (length - before) / max(1e-9, (length - before) + after)
                at_ms = self.start_epoch_ms + round((t_before + fraction * self.physics.dt) * 1000)
                with self._lock:
                    self.crossings.append((at_ms, VIRTUAL_STRIP_SENSOR))
            self._s = after
            if abs(self._offset) > self._half + 0.05:
                self._reset_on_centre_line()

    def _reset_on_centre_line(self) -> None:
        x, y, heading = self.track.pose_at(self._s)
        self.physics.reset(x, y, heading)
        self.resets += 1
        self._s = self._arc()

    def drain_crossings(self) -> list[tuple[int, int]]:
        with self._lock:
            crossings, self.crossings = self.crossings, []
        return crossings

    def steering_to_centre(self, lookahead_m: float = 0.6) -> float:
        """A pure-pursuit steering angle (degrees) towards the centre line ahead: the sim's stand-in driver."""
        x, y, heading = self.pose()
        tx, ty, _ = self.track.pose_at(self._s + lookahead_m)
        angle = math.atan2(ty - y, tx - x) - heading
        angle = math.atan2(math.sin(angle), math.cos(angle))
        steer = math.atan2(2 * self.physics.spec.wheelbase * math.sin(angle), lookahead_m)
        return max(-30.0, min(30.0, math.degrees(steer)))
