"""Typed rule violations. The HTTP layer maps these (by class and ``code``) to 409/404/422 in one place."""
from __future__ import annotations


class RaceRuleError(Exception):
    """A command the race's rules do not allow; ``str(error)`` is a sentence an operator can read."""

    code = "race_rule"

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class IllegalCommandError(RaceRuleError):
    """The command is not allowed in the race's current state."""

    code = "illegal_command"


class LapNotFoundError(RaceRuleError):
    code = "lap_not_found"
