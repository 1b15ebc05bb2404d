"""A donkeycar-style drive loop: parts read named channels, run, and write named channels, at a fixed rate.

    vehicle = Vehicle()
    vehicle.add(camera, outputs=[CAMERA_IMAGE, CAMERA_FRAME_TIME])
    vehicle.add(pilot, inputs=[CAMERA_IMAGE], outputs=[PILOT_STEERING, PILOT_SPEED], run_condition=PILOT_ENABLED)
    stats = vehicle.start(rate_hz=15, max_loops=100)

The scheduler keeps absolute deadlines on the monotonic clock (tick n is due at start + n/rate), so a slow tick does
not push every later tick back; a tick that overruns by more than a whole period skips ahead instead of bursting.
Per-part run times and the loop's lateness (jitter) are measured so a car can report them.
"""
from __future__ import annotations

import statistics
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol


class Part(Protocol):
    def run(self, *inputs: Any) -> Any: ...


@dataclass
class _Entry:
    part: Any
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    run_condition: str | None
    name: str


@dataclass
class LoopStats:
    loops: int = 0
    overruns: int = 0
    jitter_ms: list[float] = field(default_factory=list)
    part_ms: dict[str, list[float]] = field(default_factory=dict)
    elapsed_s: float = 0.0

    @property
    def rate_hz(self) -> float:
        return self.loops / self.elapsed_s if self.elapsed_s > 0 else 0.0

    def summary(self) -> dict[str, Any]:
        def pct(values: list[float], q: float) -> float:
            return round(sorted(values)[min(len(values) - 1, int(q * len(values)))], 3) if values else 0.0

        return {"loops": self.loops, "rate_hz": round(self.rate_hz, 2), "overruns": self.overruns,
                "jitter_ms_p50": pct(self.jitter_ms, 0.5), "jitter_ms_p99": pct(self.jitter_ms, 0.99),
                "parts_ms_median": {name: round(statistics.median(v), 3) for name, v in self.part_ms.items() if v}}


class Vehicle:
    def __init__(self, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.memory: dict[str, Any] = {}
        self._entries: list[_Entry] = []
        self._clock = clock
        self._sleep = sleep
        self._stop = threading.Event()
        self.stats = LoopStats()

    def add(self, part: Any, inputs: Sequence[str] = (), outputs: Sequence[str] = (),
            run_condition: str | None = None, name: str | None = None) -> None:
        if not callable(getattr(part, "run", None)):
            raise TypeError(f"{part!r} has no run() method, so it cannot be a vehicle part")
        self._entries.append(_Entry(part, tuple(inputs), tuple(outputs), run_condition,
                                    name or type(part).__name__))

    def stop(self) -> None:
        """Ask the loop to finish after the current tick (safe from another thread or a part)."""
        self._stop.set()

    def run_once(self) -> None:
        for entry in self._entries:
            if entry.run_condition is not None and not self.memory.get(entry.run_condition):
                continue
            started = time.perf_counter()
            result = entry.part.run(*(self.memory.get(key) for key in entry.inputs))
            self.stats.part_ms.setdefault(entry.name, []).append((time.perf_counter() - started) * 1000)
            self._store(entry, result)

    def _store(self, entry: _Entry, result: Any) -> None:
        if not entry.outputs:
            return
        if len(entry.outputs) == 1:
            self.memory[entry.outputs[0]] = result
            return
        if result is None:
            result = (None,) * len(entry.outputs)
        if len(result) != len(entry.outputs):
            raise ValueError(f"part {entry.name} returned {len(result)} values for outputs {entry.outputs}")
        self.memory.update(zip(entry.outputs, result, strict=True))

    def start(self, rate_hz: float = 15.0, max_loops: int | None = None) -> LoopStats:
        if rate_hz <= 0:
            raise ValueError("rate_hz must be positive")
        period = 1.0 / rate_hz
        self._stop.clear()
        self.stats = LoopStats()
        start = self._clock()
        next_due = start
        try:
            while not self._stop.is_set() and (max_loops is None or self.stats.loops < max_loops):
                now = self._clock()
                self.stats.jitter_ms.append(max(0.0, now - next_due) * 1000)
                self.run_once()
                self.stats.loops += 1
                next_due += period
                now = self._clock()
                if now > next_due + period:
                    # More than a whole period late: skip missed ticks rather than run a burst of them.
                    self.stats.overruns += 1
                    next_due = now
                elif next_due > now:
                    self._sleep(next_due - now)
        finally:
            self.stats.elapsed_s = self._clock() - start
            self.shutdown()
        return self.stats

    def shutdown(self) -> None:
        for entry in reversed(self._entries):
            closer = getattr(entry.part, "shutdown", None)
            if callable(closer):
                closer()
