"""The demonstrator: a pure-pursuit driver on the centre line, the teacher behaviour cloning copies.

Steering aims the rear axle at the centre line `lookahead` metres ahead (pure pursuit on a
bicycle). Speed comes from a profile computed once per track: each waypoint's limit is what the
curvature allows at `lateral_accel`, then a backward pass lowers it so the car can brake in time
for the next bend. Optional steering noise (from an injected numpy Generator) widens the
recorded states so a cloned model also learns to recover.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from drem_sim.physics import CarSpec
from drem_sim.tracks import Track


@dataclass(frozen=True)
class DemonstratorConfig:
    max_speed: float = 2.2  # m/s on straights (elite physical laps average ~2.3 m/s)
    min_speed: float = 0.8
    lateral_accel: float = 3.0  # m/s² allowed in bends (grip is ~9.8: a wide margin for tracking error)
    brake_decel: float = 3.0  # m/s² assumed when planning braking for a bend
    lookahead_base: float = 0.3  # m
    lookahead_per_speed: float = 0.2  # extra lookahead per m/s
    curvature_window_m: float = 0.4  # curvature is the mean heading change over this stretch
    steering_noise_deg: float = 0.0  # Gaussian noise on steering (needs an rng)


class Demonstrator:
    def __init__(self, track: Track, config: DemonstratorConfig | None = None, car: CarSpec | None = None,
                 rng: np.random.Generator | None = None) -> None:
        self.track = track.require_racing_loop()
        self.config = config or DemonstratorConfig()
        self.car = car or CarSpec()
        self.rng = rng
        self.speed_profile = self._speed_profile()

    # ---- planning -------------------------------------------------------------------------
    def curvature(self) -> np.ndarray:
        """|curvature| (1/m) at each waypoint, averaged over `curvature_window_m` to tame noisy routes."""
        track = self.track
        pts = track.centerline
        seg = np.roll(pts, -1, axis=0) - pts
        heading = np.unwrap(np.arctan2(seg[:, 1], seg[:, 0]))
        lengths = np.hypot(seg[:, 0], seg[:, 1])
        s = np.concatenate([[0.0], np.cumsum(lengths)])[:-1]
        # Sample the unwrapped heading on a closed loop: extend by one lap on both sides.
        total_turn = heading[-1] - heading[0] + _wrap(heading[0] - heading[-1])
        ext_h = np.concatenate([heading - total_turn, heading, heading + total_turn])
        half = self.config.curvature_window_m / 2
        # Heading of segment i applies to its midpoint.
        mid = s + lengths / 2
        ext_mid = np.concatenate([mid - track.length, mid, mid + track.length])
        ahead = np.interp(s + half, ext_mid, ext_h)
        behind = np.interp(s - half, ext_mid, ext_h)
        return np.abs(ahead - behind) / (2 * half)

    def _speed_profile(self) -> np.ndarray:
        cfg = self.config
        kappa = self.curvature()
        limit = np.sqrt(cfg.lateral_accel / np.maximum(kappa, 1e-6))
        v = np.clip(limit, cfg.min_speed, cfg.max_speed)
        lengths = np.diff(self.track.cumulative)
        n = len(v)
        # Braking: v_i² <= v_{i+1}² + 2·a·d_i, swept backwards twice round the loop.
        for _ in range(2):
            for i in range(n - 1, -1, -1):
                nxt = v[(i + 1) % n]
                v[i] = min(v[i], math.sqrt(nxt * nxt + 2 * cfg.brake_decel * lengths[i]))
        return v

    def target_speed(self, s: float) -> float:
        track = self.track
        s = s % track.length
        i = int(np.searchsorted(track.cumulative, s, side="right") - 1) % track.n_waypoints
        return float(min(self.speed_profile[i], self.speed_profile[(i + 1) % track.n_waypoints]))

    # ---- acting ---------------------------------------------------------------------------
    def act(self, state: Mapping[str, Any]) -> dict[str, float]:
        """An action from DeepRacer params (x, y = front point, heading in degrees, projection_distance)
        or from a car state (x, y = car origin, heading in radians, as `RaceEnv.car_state()`)."""
        if "projection_distance" in state:
            heading = math.radians(float(state["heading"]))
            front = self.car.front_point_x
            fx, fy = float(state["x"]), float(state["y"])
            s = float(state["projection_distance"])
        else:
            heading = float(state["heading"])
            front = 0.0
            fx, fy = float(state["x"]), float(state["y"])
            s = float(self.track.project((fx, fy)).s[0])
        c, h = math.cos(heading), math.sin(heading)
        back = front - self.car.rear_axle_x  # front point -> rear axle
        rx, ry = fx - back * c, fy - back * h
        speed = self.target_speed(s)
        lookahead = self.config.lookahead_base + self.config.lookahead_per_speed * speed
        tx, ty, _ = self.track.pose_at(s + lookahead)
        dx, dy = tx - rx, ty - ry
        alpha = _wrap(math.atan2(dy, dx) - heading)
        distance = max(math.hypot(dx, dy), 1e-3)
        steering = math.degrees(math.atan2(2.0 * self.car.wheelbase * math.sin(alpha), distance))
        if self.rng is not None and self.config.steering_noise_deg > 0:
            steering += float(self.rng.normal(0.0, self.config.steering_noise_deg))
        limit = self.car.max_steering_deg
        return {"steering_angle": max(-limit, min(limit, steering)), "speed": speed}


def _wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))
