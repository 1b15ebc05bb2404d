"""The drive loop. Its schedule is checked on a fake clock (`FakeTime`): what it asks to sleep, and when each tick
runs, are exact there, and no test waits for real time to pass."""
from __future__ import annotations

import pytest

from drem_cars.vehicle import Vehicle

pytestmark = pytest.mark.unit


class FakeTime:
    """A monotonic clock that moves only when the loop sleeps or a part says it took time."""

    def __init__(self) -> None:
        self.now = 100.0
        self.slept: list[float] = []

    def clock(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.slept.append(seconds)
        self.now += seconds


class Counter:
    def __init__(self) -> None:
        self.n = 0

    def run(self) -> int:
        self.n += 1
        return self.n


class Doubler:
    def run(self, value: int) -> tuple[int, int]:
        return value, value * 2


class Closable:
    closed = False

    def run(self) -> None: ...

    def shutdown(self) -> None:
        self.closed = True


def test_parts_pass_values_through_named_channels_for_a_bounded_run() -> None:
    vehicle = Vehicle()
    closable = Closable()
    vehicle.add(Counter(), outputs=["count"])
    vehicle.add(Doubler(), inputs=["count"], outputs=["same", "double"])
    vehicle.add(closable)
    stats = vehicle.start(rate_hz=500, max_loops=5)
    assert stats.loops == 5
    assert vehicle.memory == {"count": 5, "same": 5, "double": 10}
    assert closable.closed, "shutdown() runs when the loop ends"
    assert set(stats.summary()["parts_ms_median"]) == {"Counter", "Doubler", "Closable"}


def test_run_condition_gates_a_part() -> None:
    vehicle = Vehicle()
    gated = Counter()
    vehicle.add(gated, outputs=["n"], run_condition="enabled")
    vehicle.start(rate_hz=500, max_loops=3)
    assert gated.n == 0
    vehicle.memory["enabled"] = True
    vehicle.start(rate_hz=500, max_loops=3)
    assert gated.n == 3


def test_fixed_rate_keeps_deadlines_and_measures_jitter() -> None:
    fake = FakeTime()

    class TakesFiveMs:
        def run(self) -> float:
            fake.now += 0.005
            return fake.now

    vehicle = Vehicle(clock=fake.clock, sleep=fake.sleep)
    vehicle.add(TakesFiveMs(), outputs=["ran_until"])
    stats = vehicle.start(rate_hz=50, max_loops=10)
    assert fake.slept == pytest.approx([0.015] * 10), "each tick sleeps what is left of its 20 ms period"
    assert stats.elapsed_s == pytest.approx(0.2) and stats.overruns == 0
    assert stats.jitter_ms == pytest.approx([0.0] * 10) and stats.summary()["rate_hz"] == pytest.approx(50)


def test_a_late_tick_is_made_up_by_a_shorter_sleep() -> None:
    fake = FakeTime()

    class LateOnce:
        def __init__(self) -> None:
            self.n = 0

        def run(self) -> None:
            self.n += 1
            fake.now += 0.015 if self.n == 2 else 0.001  # tick 2 overruns its 10 ms period by less than a period

    vehicle = Vehicle(clock=fake.clock, sleep=fake.sleep)
    vehicle.add(LateOnce())
    stats = vehicle.start(rate_hz=100, max_loops=4)
    assert fake.slept == pytest.approx([0.009, 0.004, 0.009]), \
        "no sleep after the late tick 2; tick 3 runs 5 ms late and sleeps only 4 ms to be back on schedule"
    assert stats.jitter_ms == pytest.approx([0.0, 0.0, 5.0, 0.0]) and stats.overruns == 0


def test_an_overrunning_tick_skips_ahead_instead_of_bursting() -> None:
    fake = FakeTime()
    started_at: list[float] = []

    class SlowFirstTick:
        def run(self) -> None:
            started_at.append(fake.now)
            fake.now += 0.05 if len(started_at) == 1 else 0.001  # the first tick takes five periods at 100 Hz

    vehicle = Vehicle(clock=fake.clock, sleep=fake.sleep)
    vehicle.add(SlowFirstTick())
    stats = vehicle.start(rate_hz=100, max_loops=4)
    assert stats.overruns == 1
    assert started_at == pytest.approx([100.0, 100.05, 100.06, 100.07]), \
        "after the overrun the loop runs on at its rate from now, not a burst of the four missed ticks"


def test_stop_from_a_part_ends_the_loop() -> None:
    vehicle = Vehicle()

    class Stopper:
        def run(self) -> None:
            vehicle.stop()

    vehicle.add(Stopper())
    assert vehicle.start(rate_hz=100).loops == 1


def test_a_part_without_run_is_refused() -> None:
    with pytest.raises(TypeError, match="run"):
        Vehicle().add(object())
