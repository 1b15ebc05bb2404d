"""Wake-ups for cars waiting on their assignment: the writer of an assignment wakes the long polls waiting on it.

In-process and per car: `AssignmentService` calls `changed(device_id)` after each write it makes, and a car's long poll
(`AssignmentService.for_car`) sleeps on `wait(...)` instead of re-reading storage. The app behind waitress is one
process with several worker threads, so a staff request on one thread wakes a car's poll held by another at once.

Not in storage, so nothing to survive: after an app restart the car's poll is cut, the agent asks again, and that first
read of storage answers any change made meanwhile. A write this process did not make (another process, or on AWS
another Lambda execution environment, which a waiting Lambda cannot hear) is found by the waiting poll's storage
re-read every `recheck_s` (settings.assignment_recheck_s): the fallback.
"""
from __future__ import annotations

import threading


class AssignmentSignals:
    def __init__(self) -> None:
        self._changed = threading.Condition()
        self._writes: dict[str, int] = {}  # writes seen per car since this process started (one int per car)

    def mark(self, device_id: str) -> int:
        """Take before reading the car's assignment: a write after the read then makes `wait` return at once."""
        with self._changed:
            return self._writes.get(device_id, 0)

    def changed(self, device_id: str) -> None:
        with self._changed:
            self._writes[device_id] = self._writes.get(device_id, 0) + 1
            self._changed.notify_all()

    def wait(self, device_id: str, mark: int, timeout_s: float) -> bool:
        """True as soon as the car's assignment was written after `mark`; False after `timeout_s` without a write."""
        with self._changed:
            return self._changed.wait_for(lambda: self._writes.get(device_id, 0) != mark, timeout=timeout_s)
