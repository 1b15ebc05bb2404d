"""The car: steering servo slew, speed tracking, and tyres that let go when a bend is taken too fast."""
from __future__ import annotations

import math

import pytest

from drem_sim.physics import CarPhysics

pytestmark = pytest.mark.sim


def _drive(car: CarPhysics, seconds: float) -> None:
    for _ in range(round(seconds / car.dt)):
        car.step()


def test_straight_line_reaches_the_commanded_speed_and_holds_heading() -> None:
    car = CarPhysics()
    car.reset(0.0, 0.0, 0.0)
    car.command(0.0, 2.0)
    _drive(car, 2.0)
    assert car.speed == pytest.approx(2.0, abs=1e-6)
    assert car.heading == pytest.approx(0.0) and car.y == pytest.approx(0.0)
    assert 3.0 < car.x < 4.0  # accelerates at 6 m/s² for a third of a second, then cruises


def test_slow_turn_follows_the_bicycle_radius() -> None:
    car = CarPhysics()
    car.reset(0.0, 0.0, 0.0, speed=0.5)
    car.command(20.0, 0.5)
    _drive(car, 0.5)  # the servo has settled
    rate = 0.5 * math.tan(math.radians(20.0)) / car.spec.wheelbase
    before = car.heading
    _drive(car, 0.5)
    assert car.heading - before == pytest.approx(rate * 0.5, rel=0.02)
    assert not car.sliding


def test_too_fast_into_a_tight_bend_slides_wide() -> None:
    def radius_of(speed: float) -> float:
        car = CarPhysics()
        car.reset(0.0, 0.0, 0.0, speed=speed)
        car.command(30.0, speed)
        _drive(car, 0.3)
        points = []
        slid = False
        for _ in range(60):
            car.step()
            slid |= car.sliding
            points.append((car.x, car.y))
        xs, ys = zip(*points, strict=True)
        return (max(xs) - min(xs) + max(ys) - min(ys)) / 4, slid

    slow, slow_slid = radius_of(0.5)
    fast, fast_slid = radius_of(3.5)
    assert not slow_slid and fast_slid
    assert fast > 2 * slow


def test_steering_is_rate_limited_and_clipped() -> None:
    car = CarPhysics(dt=1 / 60)
    car.reset(0.0, 0.0, 0.0)
    car.command(90.0, 1.0)
    car.step()
    assert math.degrees(car.steer) == pytest.approx(6.0)  # 360 °/s servo, one 1/60 s step
    _drive(car, 0.5)
    assert math.degrees(car.steer) == pytest.approx(30.0)
