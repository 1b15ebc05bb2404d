from __future__ import annotations

from pathlib import Path

import pytest
from gpiozero import Device
from gpiozero.pins.mock import MockFactory

from drem_cars.outbox import Outbox
from drem_cars.parts.timing_strips import CrossingFilter, TimingStrips

pytestmark = pytest.mark.unit


@pytest.fixture
def mock_pins():
    previous = Device.pin_factory
    Device.pin_factory = MockFactory()
    yield Device.pin_factory
    Device.pin_factory.reset()
    Device.pin_factory = previous


class Clock:
    def __init__(self) -> None:
        self.ms = 1_700_000_000_000

    def __call__(self) -> int:
        return self.ms


def press(factory: MockFactory, pin: int) -> None:
    factory.pin(pin).drive_high()
    factory.pin(pin).drive_low()


def test_strip_presses_become_outbox_events_with_debounce_and_minimum_lap(tmp_path: Path, mock_pins) -> None:
    outbox = Outbox(tmp_path / "o.sqlite3")
    clock = Clock()
    strips = TimingStrips(outbox, "ev1", "1", "timer-1", clock_ms=clock)
    try:
        press(mock_pins, 17)                 # t=0: the car's front wheels: a crossing
        clock.ms += 150
        press(mock_pins, 17)                 # rear wheels on the same strip: debounce
        press(mock_pins, 27)                 # the other strip 150 ms later: the same crossing (3 s rule)
        clock.ms += 9_850
        press(mock_pins, 27)                 # t=10 s: next lap, on the other strip
        clock.ms += 1_000
        press(mock_pins, 17)                 # t=11 s: too soon after a counted crossing
    finally:
        strips.close()
    events = [item.body for item in outbox.pending()]
    assert [(e["sensor"], e["timestamp_ms"] - 1_700_000_000_000) for e in events] == [(17, 0), (27, 10_000)]
    assert {e["event_id"] for e in events} == {"ev1"} and len({e["idempotency_key"] for e in events}) == 2
    assert strips.ignored == 3


def test_a_bounce_does_not_move_the_sensor_clock_forward() -> None:
    rules = CrossingFilter()
    assert rules.accept(17, 0)
    assert not rules.accept(17, 1_500)
    assert rules.accept(17, 3_100), "the debounce counts from the first trigger, not from the bounce"
