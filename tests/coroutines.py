"""Running a test's coroutine to completion whatever the worker ran before it.

pytest-xdist runs many files in one worker process; after a browser test there, Playwright's sync API keeps an event
loop marked as running in the main thread, and `asyncio.run` refuses to start inside it. A fresh thread has no
running loop, so the coroutine gets its own, exactly as `asyncio.run` would give it."""
from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

T = TypeVar("T")


def run(coroutine: Coroutine[Any, Any, T]) -> T:
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="test-coroutine") as thread:
        return thread.submit(asyncio.run, coroutine).result()
