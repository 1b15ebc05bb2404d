"""Two pressure strips on a Raspberry Pi (BCM GPIO17 and GPIO27, as DREM's timer) → strip events in the outbox.

A strip's comparator board drives its pin high while pressed; each rising edge is a crossing. Per-sensor debounce
(2 s: one car's wheels bounce a strip several times) and a global minimum lap time (3 s: a car pressing both strips is
one crossing) are applied here, so the outbox holds only real crossings; the server applies the same rules again.
Timestamps are the Pi's wall clock in ms (keep it on NTP).
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable

from drem_cars.outbox import STRIP_EVENT, Outbox
from drem_cars.parts.strips import strip_event

DEFAULT_PINS = (17, 27)
DEBOUNCE_MS = 2000
MIN_LAP_MS = 3000


class CrossingFilter:
    """Pure rules: is a rising edge on `sensor` at `at_ms` a crossing to report?"""

    def __init__(self, debounce_ms: int = DEBOUNCE_MS, min_lap_ms: int = MIN_LAP_MS) -> None:
        self.debounce_ms = debounce_ms
        self.min_lap_ms = min_lap_ms
        self._last_trigger: dict[int, int] = {}
        self._last_counted: int | None = None

    def accept(self, sensor: int, at_ms: int) -> bool:
        last = self._last_trigger.get(sensor)
        if last is not None and at_ms - last < self.debounce_ms:
            return False  # a bounce: the sensor's clock is not moved
        self._last_trigger[sensor] = at_ms
        if self._last_counted is not None and at_ms - self._last_counted < self.min_lap_ms:
            return False
        self._last_counted = at_ms
        return True


class TimingStrips:
    def __init__(self, outbox: Outbox, event_id: str, track_id: str, device_id: str,
                 pins: tuple[int, ...] = DEFAULT_PINS, *, clock_ms: Callable[[], int] | None = None,
                 crossing_filter: CrossingFilter | None = None) -> None:
        from gpiozero import DigitalInputDevice

        self.outbox = outbox
        self.event_id = event_id
        self.track_id = track_id
        self.device_id = device_id
        self.filter = crossing_filter or CrossingFilter()
        self._clock_ms = clock_ms or (lambda: time.time_ns() // 1_000_000)
        self._lock = threading.Lock()
        self.queued = 0
        self.ignored = 0
        self.sensors = []
        for pin in pins:
            sensor = DigitalInputDevice(pin, pull_up=False)
            sensor.when_activated = self._handler(pin)
            self.sensors.append(sensor)

    def _handler(self, pin: int) -> Callable[[], None]:
        def crossed() -> None:
            self.crossing(pin, self._clock_ms())
        return crossed

    def crossing(self, sensor: int, at_ms: int) -> bool:
        with self._lock:
            if not self.filter.accept(sensor, at_ms):
                self.ignored += 1
                return False
            body = strip_event(self.event_id, self.track_id, at_ms, sensor, self.device_id)
            self.outbox.enqueue(STRIP_EVENT, body, body["idempotency_key"])
            self.queued += 1
            return True

    def close(self) -> None:
        for sensor in self.sensors:
            sensor.close()
