"""The env's shortcuts (pose integrated in Python with Chipmunk's arithmetic, wheel points from the pose's kept
cos/sin, wheel offsets kept per pose, the on-track check stopping at the first wheel on the track) change nothing:
the same actions give bit-identical trajectories, params and camera frames as the plain formulation on a real
pymunk Space."""
from __future__ import annotations

import math

import numpy as np
import pytest

from drem_sim.demonstrator import Demonstrator, DemonstratorConfig
from drem_sim.env import RaceEnv
from drem_sim.physics import CarPhysics
from drem_sim.tracks import load_track

pytestmark = pytest.mark.sim


class PlainEnv(RaceEnv):
    """The straightforward formulation: pymunk steps the body, every wheel point comes from `point_ahead`,
    every wheel offset is recomputed."""

    def __init__(self, track) -> None:  # noqa: ANN001
        super().__init__(track)
        self.physics = CarPhysics(self.physics.spec, dt=self.physics.dt, integrator="pymunk")

    def _wheel_offsets(self) -> list[tuple[float, float]]:
        sp, physics = self.physics.spec, self.physics
        half = sp.axle_track / 2
        c, s = math.cos(physics.heading), math.sin(physics.heading)  # afresh, not the pose's kept cos/sin
        points = [(physics.x + fx * c - side * s, physics.y + fx * s + side * c)
                  for fx in (sp.front_axle_x, sp.rear_axle_x) for side in (half, -half)]
        return [self.track.locate(wx, wy, self._hint, back=4, ahead=2)[2:] for wx, wy in points]

    def _any_wheel_on_track(self) -> bool:
        if abs(self._offset) < self._half - 0.3:
            return True
        return any(abs(offset) <= half for offset, half in self._wheel_offsets())


@pytest.mark.parametrize("track_name", ["reinvent_base", "2024_reinvent_champ_ccw"])
def test_fast_env_matches_the_plain_formulation_bit_for_bit(track_name: str) -> None:
    track = load_track(track_name)
    fast, plain = RaceEnv(track), PlainEnv(track)
    # A wild driver (12 deg steering noise, too fast) so the car grazes borders and leaves the track.
    config = DemonstratorConfig(steering_noise_deg=12.0, max_speed=3.2, lateral_accel=6.0)
    drivers = [Demonstrator(track, config, rng=np.random.default_rng(5)) for _ in range(2)]
    (obs_a, info_a), (obs_b, info_b) = fast.reset(seed=1), plain.reset(seed=1)
    params_a, params_b = info_a["params"], info_b["params"]
    border_checks = 0
    for _ in range(600):
        assert np.array_equal(obs_a, obs_b)
        obs_a, params_a, *_rest_a, info_a = fast.step(drivers[0].act(params_a))
        obs_b, params_b, *_rest_b, info_b = plain.step(drivers[1].act(params_b))
        assert params_a == params_b
        assert fast.car_state() == plain.car_state()
        border_checks += not (abs(fast._offset) < fast._half - 0.3)
    assert fast.resets == plain.resets and fast.resets > 0, "the drive should leave the track at least once"
    assert border_checks > 50  # the exact wheel check really ran, not only the centre-line shortcut
    assert fast.laps == plain.laps and fast.lap_times_s == plain.lap_times_s
    assert plain.physics.integrator == "pymunk" and fast.physics.integrator == "python"


def test_python_integrator_moves_the_body_exactly_as_a_pymunk_space_step() -> None:
    """Arbitrary velocities (sliding, braking, spinning): the pose after every step is the same float."""
    python, pymunk_car = CarPhysics(integrator="python"), CarPhysics(integrator="pymunk")
    rng = np.random.default_rng(11)
    for car in (python, pymunk_car):
        car.reset(1.25, -3.5, 2.9, speed=1.0)
    slides = 0
    for step in range(3000):
        steering, speed = float(rng.uniform(-30, 30)), float(rng.uniform(0, 4))
        for car in (python, pymunk_car):
            car.command(steering, speed)
            car.step()
        slides += python.sliding
        assert (python.x, python.y, python.heading, python.vx, python.vy, python.sliding) == \
            (pymunk_car.x, pymunk_car.y, pymunk_car.heading, pymunk_car.vx, pymunk_car.vy, pymunk_car.sliding), step
    assert slides > 10  # the grip limit's sliding branch ran too
    body = python.body  # the pymunk body is kept up to date for anyone who asks for it
    assert (body.position.x, body.position.y, body.angle) == (python.x, python.y, python.heading)
    with pytest.raises(ValueError, match="integrator"):
        CarPhysics(integrator="verlet")
