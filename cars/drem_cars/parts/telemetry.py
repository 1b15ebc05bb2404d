"""Part: a rolling frame rate and inference latency, read by the agent for its heartbeats."""
from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable


class Telemetry:
    def __init__(self, window: int = 45, clock: Callable[[], float] = time.monotonic) -> None:
        self._frames: collections.deque[float] = collections.deque(maxlen=window)
        self._inference: collections.deque[float] = collections.deque(maxlen=window)
        self._lock = threading.Lock()
        self._clock = clock

    def run(self, frame_time: float | None, inference_ms: float | None) -> tuple[float | None, float | None]:
        with self._lock:
            if frame_time is not None and (not self._frames or frame_time != self._frames[-1]):
                self._frames.append(frame_time)
            if inference_ms is not None:
                self._inference.append(inference_ms)
        return self.fps(), self.inference_ms()

    def fps(self) -> float | None:
        with self._lock:
            if len(self._frames) < 2 or self._frames[-1] <= self._frames[0]:
                return None
            return round((len(self._frames) - 1) / (self._frames[-1] - self._frames[0]), 2)

    def inference_ms(self) -> float | None:
        with self._lock:
            if not self._inference:
                return None
            ordered = sorted(self._inference)
            return round(ordered[len(ordered) // 2], 3)
