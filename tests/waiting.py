"""Wait for what a test cares about, not for a fixed time.

    loaded = wait_until(lambda: status() == "loaded", 30, "the car reports the model loaded")

The timeout only bounds a failure: a passing test waits as long as the condition takes and no longer. Pick it
generously (a loaded, shared machine is slow); the test fails with `what` if it passes.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

import pytest

T = TypeVar("T")


def wait_until(condition: Callable[[], T], timeout_s: float, what: str, poll_s: float = 0.05) -> T:
    """Call `condition` until it returns something truthy, and return that; fail the test with `what` after
    `timeout_s` seconds. The condition is checked once more at the deadline, so a slow last poll still counts."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() >= deadline:
            pytest.fail(f"timed out after {timeout_s:.0f} s waiting for: {what}")
        time.sleep(poll_s)
