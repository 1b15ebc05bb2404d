from __future__ import annotations

import time

import pytest

from drem_cars.vehicle import Vehicle

pytestmark = pytest.mark.unit


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
    vehicle = Vehicle()
    vehicle.add(Counter(), outputs=["n"])
    started = time.monotonic()
    stats = vehicle.start(rate_hz=50, max_loops=10)
    elapsed = time.monotonic() - started
    assert 0.17 <= elapsed < 0.6, "10 ticks at 50 Hz take about 9 periods"
    assert len(stats.jitter_ms) == 10 and stats.summary()["jitter_ms_p99"] >= 0


def test_an_overrunning_tick_skips_ahead_instead_of_bursting() -> None:
    class Slow:
        def run(self) -> None:
            time.sleep(0.05)

    vehicle = Vehicle()
    vehicle.add(Slow())
    stats = vehicle.start(rate_hz=100, max_loops=3)
    assert stats.overruns >= 2


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
