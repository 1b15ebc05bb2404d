"""The virtual timing strip reports forward crossings, interpolated inside the physics step."""
from __future__ import annotations

import math

import pytest

from drem_sim.env import EnvConfig, RaceEnv
from drem_sim.physics import CarPhysics
from drem_sim.timing import TimingConfig, TimingLine

pytestmark = pytest.mark.sim


def test_crossing_time_matches_the_analytic_crossing_within_a_millisecond() -> None:
    """A car at constant speed on a straight: the strip time equals line distance / speed."""
    speed, line_x, epoch = 2.37, 1.0, 1_700_000_000_000
    car = CarPhysics(dt=1.0 / 60.0)
    car.reset(0.0, 0.0, 0.0, speed=speed)
    car.command(0.0, speed)
    line = TimingLine(((line_x, -0.5), (line_x, 0.5)), forward=(1.0, 0.0),
                      config=TimingConfig(device_id="car-7", epoch_ms=epoch))
    t = 0.0
    line.jump(t, *car.front_point())
    events = []
    while t < 1.0:
        car.step()
        t += car.dt
        event = line.observe(t, *car.front_point())
        if event:
            events.append(event)
    assert len(events) == 1
    analytic_ms = epoch + (line_x - car.spec.front_point_x) / speed * 1000.0
    assert abs(events[0]["timestamp_ms"] - analytic_ms) <= 1.0
    # The crossing falls mid-tick: reporting the tick's time instead would be several ms off.
    tick_ms = epoch + math.ceil((analytic_ms - epoch) / (car.dt * 1000)) * car.dt * 1000
    assert abs(tick_ms - analytic_ms) > 3.0
    assert events[0] == {"timestamp_ms": events[0]["timestamp_ms"], "sensor": 17, "idempotency_key": "car-7-1"}


def test_backward_crossings_and_misses_are_not_presses() -> None:
    line = TimingLine(((0.0, -0.5), (0.0, 0.5)), forward=(1.0, 0.0), config=TimingConfig(debounce_ms=0))
    line.jump(0.0, 0.5, 0.0)
    assert line.observe(0.1, -0.5, 0.0) is None  # backwards over the line
    assert line.observe(0.2, 0.5, 2.0) is None  # forwards, but beside the strip
    line.jump(0.3, -0.5, 0.0)
    assert line.observe(0.4, 0.5, 0.0)["idempotency_key"] == "sim-timer-1"
    line.jump(0.5, -0.5, 0.0)  # a teleport back is not a crossing either
    assert line.observe(0.6, 0.5, 0.0)["idempotency_key"] == "sim-timer-2"


def test_presses_within_the_debounce_window_are_ignored_like_the_hardware() -> None:
    line = TimingLine(((0.0, -0.5), (0.0, 0.5)), forward=(1.0, 0.0), config=TimingConfig(debounce_ms=2000))
    line.jump(0.0, -0.1, 0.0)
    assert line.observe(0.1, 0.1, 0.0) is not None
    line.jump(1.0, -0.1, 0.0)
    assert line.observe(1.1, 0.1, 0.0) is None
    line.jump(3.0, -0.1, 0.0)
    assert line.observe(3.1, 0.1, 0.0) is not None


def test_env_reports_one_strip_event_per_lap_matching_its_lap_times() -> None:
    from drem_sim.demonstrator import Demonstrator

    epoch = 1_000_000
    env = RaceEnv("reinvent_base", EnvConfig(observe=False, max_laps=2,
                                             timing=TimingConfig(device_id="timer-a", epoch_ms=epoch)))
    driver = Demonstrator(env.track)
    _, info = env.reset(seed=0)
    params, events, done = info["params"], [], False
    while not done:
        _, params, terminated, truncated, info = env.step(driver.act(params))
        events += info["strip_events"]
        done = terminated or truncated
    assert [e["idempotency_key"] for e in events] == ["timer-a-1", "timer-a-2"]
    laps_ms = [events[0]["timestamp_ms"] - epoch, events[1]["timestamp_ms"] - events[0]["timestamp_ms"]]
    for strip_ms, lap_s in zip(laps_ms, info["lap_times_s"], strict=False):
        assert math.isclose(strip_ms, lap_s * 1000, abs_tol=3.0)
