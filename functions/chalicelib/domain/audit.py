"""The audit trail of an event's results: who changed what, when, from what to what.

Recorded for every change that can move a result after the fact: a lap edit in race admin, a lap validity toggle
(race admin or timekeeper), a race deleted, the boards recomputed, the event imported. Entries live next to the
races (same table, `EVENT#{id}` / `AUDIT#{at_ms}#{id}`), so `drem export` carries them with the races and an import
brings them along. Written right after the change it describes (never instead of it): the change itself is the
acknowledged write; a crash between the two loses at most that one entry, never a result.
"""
from __future__ import annotations

import uuid
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Literal, Protocol

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.formats.figures import lap_time
from drem_leaderboard.models import Lap

AuditAction = Literal["lap_edit", "lap_validity", "race_delete", "recompute", "import"]
ACTION_LABELS: dict[str, str] = {"lap_edit": "Lap edited", "lap_validity": "Lap validity changed",
                                 "race_delete": "Race deleted", "recompute": "Boards recomputed",
                                 "import": "Event imported"}


class AuditEntry(BaseModel):
    model_config = ConfigDict(frozen=True)
    entry_id: str = Field(default_factory=lambda: uuid.uuid4().hex)
    event_id: str
    at_ms: int
    by: str = Field(description="username of the staff member (or the CLI user for an import)")
    action: AuditAction
    race_id: str | None = None
    racer: str | None = None
    lap_id: int | None = None
    before: dict[str, Any] | None = None
    after: dict[str, Any] | None = None


class AuditLog(Protocol):
    def record(self, entry: AuditEntry) -> None: ...
    def for_event(self, event_id: str) -> list[AuditEntry]: ...


class AuditTrail:
    """What the race service calls: builds entries with the clock and hands them to the log (if there is one)."""

    def __init__(self, log: AuditLog | None, clock_ms: Callable[[], int]) -> None:
        self._log = log
        self._clock_ms = clock_ms

    def record(self, event_id: str, by: str, action: AuditAction, **fields: Any) -> None:
        if self._log is not None:
            self._log.record(AuditEntry(event_id=event_id, at_ms=self._clock_ms(), by=by or "unknown",
                                        action=action, **fields))


def lap_state(lap: Lap) -> dict[str, Any]:
    return {"time_ms": lap.time_ms, "resets": lap.resets, "is_valid": lap.is_valid}


def standings(board: Mapping[str, Any]) -> list[str]:
    """A board body's ranking as short lines ("1 lea 0:08.838") for a recompute's before/after."""
    return [f"{e.get('position')} {e.get('username')} {lap_time(e.get('time_ms'))}" for e in board.get("entries", [])]


def describe(state: Mapping[str, Any] | None) -> str:
    """One side of a change as staff read it on the race admin page."""
    if not state:
        return "—"
    parts = []
    if "time_ms" in state:
        parts.append(lap_time(state["time_ms"]))
    if "resets" in state:
        parts.append(f"{state['resets']} resets")
    if "is_valid" in state:
        parts.append("valid" if state["is_valid"] else "invalid")
    if "status" in state:
        fastest = lap_time(state.get("fastest_lap_ms"), "—")
        parts.append(f"{state['status']}, {state.get('laps', 0)} laps, fastest {fastest}")
    if "boards" in state:
        parts.extend(f"{board}: {', '.join(lines[:3]) or 'empty'}" for board, lines in state["boards"].items())
    if "source_event_id" in state:
        parts.append(f"from event {state['source_event_id']}")
    if "written" in state:
        parts.append(", ".join(f"{n} {table}" for table, n in state["written"].items()))
    return "; ".join(parts) or "—"


def newest_first(entries: Iterable[AuditEntry], race_id: str | None = None) -> list[AuditEntry]:
    chosen = [e for e in entries if race_id is None or e.race_id == race_id]
    return sorted(chosen, key=lambda e: (e.at_ms, e.entry_id), reverse=True)
