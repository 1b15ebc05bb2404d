"""The last part before the actuators: it alone decides whether the car may move, and how fast.

The car stops (throttle 0, wheels straight) when the camera frame is stale (older than `stale_frame_s`), when the
agent has not reached the server for longer than `heartbeat_limit_s` (staff could no longer stop it), or after an
emergency stop, which latches until the agent restarts or `clear_emergency_stop()` is called. The staff throttle cap
(0-100 %, DeepRacer's "max speed") scales every throttle.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable

STALE_FRAME_S = 0.5
HEARTBEAT_LIMIT_S = 60.0


class Safety:
    def __init__(self, *, throttle_cap_pct: int = 100, stale_frame_s: float = STALE_FRAME_S,
                 heartbeat_limit_s: float = HEARTBEAT_LIMIT_S, clock: Callable[[], float] = time.monotonic) -> None:
        self._lock = threading.Lock()
        self._clock = clock
        self.stale_frame_s = stale_frame_s
        self.heartbeat_limit_s = heartbeat_limit_s
        self._cap_pct = 100
        self.set_throttle_cap(throttle_cap_pct)
        self._emergency_stop = False
        self._last_heartbeat = clock()

    # --- called by the agent (another thread) ---
    def set_throttle_cap(self, pct: int) -> None:
        if not 0 <= pct <= 100:
            raise ValueError("the throttle cap is a percentage from 0 to 100")
        with self._lock:
            self._cap_pct = pct

    @property
    def throttle_cap_pct(self) -> int:
        return self._cap_pct

    def emergency_stop(self) -> None:
        with self._lock:
            self._emergency_stop = True

    def clear_emergency_stop(self) -> None:
        with self._lock:
            self._emergency_stop = False

    def heartbeat_ok(self) -> None:
        with self._lock:
            self._last_heartbeat = self._clock()

    # --- the part ---
    def stop_reason(self, frame_time: float | None) -> str | None:
        now = self._clock()
        with self._lock:
            if self._emergency_stop:
                return "emergency stop"
            if now - self._last_heartbeat > self.heartbeat_limit_s:
                return f"no contact with the server for {now - self._last_heartbeat:.0f} s"
        if frame_time is None:
            return "no camera frame"
        if now - frame_time > self.stale_frame_s:
            return f"camera frame is {now - frame_time:.2f} s old"
        return None

    def run(self, steering: float | None, throttle: float | None,
            frame_time: float | None) -> tuple[float, float, bool, str | None]:
        """(steering, throttle, stopped, reason) in unit values, throttle capped."""
        reason = self.stop_reason(frame_time)
        if reason is not None:
            return 0.0, 0.0, True, reason
        throttle = max(0.0, min(1.0, throttle or 0.0)) * self._cap_pct / 100.0
        return max(-1.0, min(1.0, steering or 0.0)), throttle, False, None
