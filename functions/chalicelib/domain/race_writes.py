"""Conditional race writes: a write that lost to another (`StaleRace`) reloads and applies again, a few times.

Shared by the race service and the timing strip, which both change a stored race under its version."""
from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from chalicelib.core.errors import Conflict

WRITE_ATTEMPTS = 3
T = TypeVar("T")


class StaleRace(Exception):
    """The race changed since it was read (another command or strip event won); reload and apply again."""


def with_retries(attempt: Callable[[], T]) -> T:
    for _ in range(WRITE_ATTEMPTS):
        try:
            return attempt()
        except StaleRace:
            continue
    raise Conflict("The race was changed by someone else at the same moment; try again.")
