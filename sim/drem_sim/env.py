"""RaceEnv: one car on one track, stepped at the camera rate like a DeepRacer episode.

Gym-like without depending on gymnasium: `reset(seed, options) -> (obs, info)` and
`step(action) -> (obs, params, terminated, truncated, info)`, where `params` is the DeepRacer
reward-function dict (the slot gymnasium uses for a scalar reward: a behaviour-cloning and
racing sim has no single reward, the caller scores `params` however it likes).

Each decision (15 Hz) holds the action for `physics_substeps` fixed physics steps. Leaving the
track (all four wheels outside the borders) puts the car back on the centre line at the nearest
point, at rest, and counts a reset; the lap goes on, as in a DREM race. Laps are counted from the
spawn point by distance travelled along the centre line (`laps`, `lap_times_s`: every time the car came
round, also after a put-back); `whole_laps` holds the laps that count by the one whole-lap rule
(`drem_leaderboard.laps`: driven whole from the spawn or a crossing to the next crossing without an
off-track). The virtual timing strip reports its own interpolated crossings in `info["strip_events"]`.
All randomness comes from `self.np_random`.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from drem_leaderboard.laps import LapAttempts
from drem_sim.camera import Camera, CameraConfig
from drem_sim.physics import CarPhysics, CarSpec
from drem_sim.timing import TimingConfig, TimingLine
from drem_sim.tracks import Track, load_track

DECISION_HZ = 15.0


@dataclass(frozen=True)
class EnvConfig:
    decision_hz: float = DECISION_HZ
    physics_substeps: int = 4  # fixed physics steps per decision: dt = 1 / (15 * 4) s
    max_resets: int | None = None  # terminate once the car has been put back this many times
    max_laps: int | None = None  # terminate once this many laps are complete
    max_steps: int | None = None  # truncate after this many decisions
    start_offset_m: float = 0.0  # where the front of the car spawns, metres along the centre line from waypoint 0
    random_start: bool = False  # spawn anywhere on the lap (np_random), e.g. for varied training runs
    observe: bool = True  # render camera frames; False gives obs=None (fast driving without a sensor)
    camera: CameraConfig | None = None  # default: CameraConfig.for_track(track)
    car: CarSpec = field(default_factory=CarSpec)
    timing: TimingConfig = field(default_factory=TimingConfig)

    @property
    def step_seconds(self) -> float:
        return 1.0 / self.decision_hz

    @property
    def physics_dt(self) -> float:
        return self.step_seconds / self.physics_substeps


def parse_action(action: Mapping[str, Any] | Sequence[float] | np.ndarray) -> tuple[float, float]:
    """(steering degrees, + = left; speed m/s) from `{"steering_angle", "speed"}` or a 2-sequence."""
    if isinstance(action, Mapping):
        try:
            return float(action["steering_angle"]), float(action["speed"])
        except KeyError as exc:
            raise ValueError(f"an action needs 'steering_angle' and 'speed' (missing {exc})") from None
    values = np.asarray(action, dtype=np.float64).reshape(-1)
    if values.shape != (2,):
        raise ValueError(f"an action is (steering_angle, speed); got {len(values)} values")
    return float(values[0]), float(values[1])


class RaceEnv:
    metadata = {"render_fps": DECISION_HZ}

    def __init__(self, track: Track | str, config: EnvConfig | None = None) -> None:
        self.track = (load_track(track) if isinstance(track, str) else track).require_racing_loop()
        self.config = config or EnvConfig()
        spec = self.config.car
        if spec.friction != self.track.sim.friction and spec == CarSpec():
            spec = replace(spec, friction=self.track.sim.friction)
        self.physics = CarPhysics(spec, dt=self.config.physics_dt)
        self.camera = Camera(self.track, self.config.camera) if self.config.observe else None
        self.step_seconds = self.config.step_seconds
        self.np_random = np.random.default_rng()
        self._length = self.track.length
        self._half_wheel = spec.axle_track / 2
        self._wheel_key: tuple[float, ...] | None = None
        self._wheel_cache: list[tuple[float, float]] = []  # the wheels located so far for `_wheel_key`'s pose
        self._wheel_points: list[tuple[float, float]] = []
        self._new_episode(0.0)

    # ---- episode --------------------------------------------------------------------------
    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray | None, dict]:
        """Start an episode; `options={"start_offset_m": s}` overrides the spawn point for this episode."""
        if seed is not None:
            self.np_random = np.random.default_rng(seed)
        options = options or {}
        if "start_offset_m" in options:
            start = float(options["start_offset_m"])
        elif self.config.random_start:
            start = float(self.np_random.uniform(0.0, self._length))
        else:
            start = self.config.start_offset_m
        self._new_episode(start)
        self._params: dict[str, Any] = self._make_params(False)
        return self._observe(), self._info([], False, False)

    def _new_episode(self, start_s: float) -> None:
        self.sim_time = 0.0
        self.steps = 0
        self.laps = 0
        self.lap_times_s: list[float] = []
        self.whole_laps = LapAttempts()  # the laps that count: `laps` also counts one finished after a put-back
        self.resets = 0
        self._lap_start_t = 0.0
        self._lap_distance = 0.0  # centre-line metres driven since the lap (or episode) began
        self._steering_cmd = 0.0
        self._speed_cmd = 0.0
        self.timing = TimingLine.for_track(self.track, self.config.timing)
        self._place_front_at(start_s)
        self._params = {}

    def _place_front_at(self, s: float) -> None:
        """Put the car at rest on the centre line with its front point at arc length s."""
        fx, fy, heading = self.track.pose_at(s)
        back = self.physics.spec.front_point_x
        self.physics.reset(fx - back * math.cos(heading), fy - back * math.sin(heading), heading)
        fx, fy = self.physics.front_point()
        self._hint = int(self.track.project((fx, fy)).segment[0])
        self._locate_front(fx, fy)
        self.timing.jump(self.sim_time, fx, fy)

    def _locate_front(self, fx: float, fy: float) -> None:
        seg, along, offset, half = self.track.locate(fx, fy, self._hint)
        self._hint, self._along, self._offset, self._half = seg, along, offset, half
        self._s = self.track.arc_length(seg, along)

    # ---- stepping -------------------------------------------------------------------------
    def step(self, action: Any) -> tuple[np.ndarray | None, dict[str, Any], bool, bool, dict[str, Any]]:
        steering, speed = parse_action(action)
        self.physics.command(steering, speed)
        self._steering_cmd = max(-self.physics.spec.max_steering_deg, min(self.physics.spec.max_steering_deg, steering))
        self._speed_cmd = max(0.0, min(self.physics.spec.max_speed, speed))
        events: list[dict[str, Any]] = []
        went_off = lap_done = False
        dt, length = self.physics.dt, self._length
        for _ in range(self.config.physics_substeps):
            t_before, s_before = self.sim_time, self._s
            self.physics.step()
            self.sim_time += dt
            fx, fy = self.physics.front_point()
            self._locate_front(fx, fy)
            event = self.timing.observe(self.sim_time, fx, fy)
            if event is not None:
                events.append(event)
            ds = (self._s - s_before + length / 2) % length - length / 2  # unwrap across waypoint 0
            before = self._lap_distance
            self._lap_distance += ds
            if self._lap_distance >= length:
                fraction = (length - before) / ds if ds > 0 else 1.0
                done_at = t_before + fraction * dt
                self.lap_times_s.append(done_at - self._lap_start_t)
                self.laps += 1
                self._lap_start_t = done_at
                self._lap_distance -= length
                lap_done = True
                self.whole_laps.crossed(done_at, 100.0 * self.laps)
            if not self._any_wheel_on_track():
                went_off = True
                self.resets += 1
                self.whole_laps.moved(100.0 * (self.laps + self._lap_distance / length))
                self.whole_laps.left_track()
                self._place_front_at(self._s)
        self.steps += 1
        self.whole_laps.moved(100.0 * (self.laps + self._lap_distance / length))
        self._params = self._make_params(went_off)
        cfg = self.config
        terminated = ((cfg.max_resets is not None and self.resets >= cfg.max_resets)
                      or (cfg.max_laps is not None and self.laps >= cfg.max_laps))
        truncated = cfg.max_steps is not None and self.steps >= cfg.max_steps and not terminated
        return self._observe(), self._params, terminated, truncated, self._info(events, went_off, lap_done)

    def _wheel_offsets(self) -> list[tuple[float, float]]:
        """(signed offset, half width) of each wheel contact point. The answer depends only on the pose and the
        segment hint, so it is kept for that key: the last substep's on-track check and the params of the same
        decision ask for the same pose."""
        index = 0
        while self._wheel_offset(index) is not None:
            index += 1
        return self._wheel_cache

    def _current_wheel_cache(self) -> list[tuple[float, float]]:
        physics = self.physics
        key = (physics.x, physics.y, physics.heading, self._hint)
        if key != self._wheel_key:
            self._wheel_key, self._wheel_cache = key, []
            self._wheel_points = physics.wheel_points()
        return self._wheel_cache

    def _wheel_offset(self, index: int) -> tuple[float, float] | None:
        """Wheel `index`'s (offset, half width) for the current pose, located once (None past the last wheel)."""
        cache = self._current_wheel_cache()
        if index < len(cache):
            return cache[index]
        if index >= len(self._wheel_points):
            return None
        wx, wy = self._wheel_points[index]
        _, _, offset, half = self.track.locate(wx, wy, self._hint, back=4, ahead=2)
        cache.append((offset, half))
        return offset, half

    def _any_wheel_on_track(self) -> bool:
        # Wheels are at most ~0.25 m from the front point: well inside the borders, skip the exact check.
        if abs(self._offset) < self._half - 0.3:
            return True
        # Stop at the first wheel on the track: locating the others would not change the answer (the params
        # of the decision's last substep locate the rest when they ask).
        index = 0
        while (wheel := self._wheel_offset(index)) is not None:
            if abs(wheel[0]) <= wheel[1]:
                return True
            index += 1
        return False

    # ---- outputs --------------------------------------------------------------------------
    def _observe(self) -> np.ndarray | None:
        if self.camera is None:
            return None
        p = self.physics
        return self.camera.render(p.x, p.y, p.heading, rng=self.np_random)

    def _make_params(self, went_off: bool) -> dict[str, Any]:
        track, p = self.track, self.physics
        fx, fy = p.front_point()
        n = track.n_waypoints
        all_on = abs(self._offset) < self._half - 0.3 or all(abs(o) <= h for o, h in self._wheel_offsets())
        heading = math.degrees(p.heading)
        return {
            "all_wheels_on_track": bool(all_on),
            "x": fx,
            "y": fy,
            "heading": _wrap_heading_deg(heading),
            "distance_from_center": abs(self._offset),
            "is_left_of_center": self._offset > 0,
            "progress": min(100.0, max(0.0, 100.0 * self._lap_distance / self._length)),
            "steps": self.steps,
            "speed": self._speed_cmd,
            "steering_angle": self._steering_cmd,
            "track_width": 2.0 * self._half,
            "track_length": self._length,
            "waypoints": track.waypoints,
            "closest_waypoints": [self._hint, (self._hint + 1) % n],
            "projection_distance": self._s,
            "is_reversed": track.is_reversed,
            "is_offtrack": went_off,
            "is_crashed": False,
            "sim_time": self.sim_time,
        }

    @property
    def params(self) -> dict[str, Any]:
        """The reward params of the latest reset/step."""
        return self._params

    def car_state(self) -> dict[str, float]:
        """Pose of the car origin (x, y, heading in radians) and measured speed."""
        p = self.physics
        return {"x": p.x, "y": p.y, "heading": p.heading, "speed": p.speed}

    def _info(self, events: list[dict[str, Any]], went_off: bool, lap_done: bool) -> dict[str, Any]:
        return {"params": self._params, "laps": self.laps, "lap_times_s": list(self.lap_times_s),
                "resets": self.resets, "strip_events": events, "offtrack": went_off, "lap_completed": lap_done,
                "sim_time": self.sim_time, "steps": self.steps}


def _wrap_heading_deg(angle: float) -> float:
    """Degrees in (-180, 180], as DeepRacer reports yaw."""
    wrapped = (angle + 180.0) % 360.0 - 180.0
    return 180.0 if wrapped == -180.0 else wrapped
