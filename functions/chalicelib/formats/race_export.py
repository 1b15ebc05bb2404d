"""Race admin's CSV exports ("all laps" and "racer summary") of an event's submitted races, with DREM's file names
`{event-slug}-{laps|summary}-{date}.csv` (the date is the export day, UTC)."""
from __future__ import annotations

import re
from collections.abc import Iterable
from datetime import UTC, datetime
from enum import StrEnum

from pydantic import BaseModel

from drem_leaderboard import csv_export
from drem_leaderboard.models import Race, RaceStatus
from drem_leaderboard.summary import summarise_event


class ExportKind(StrEnum):
    LAPS = "laps"
    SUMMARY = "summary"


class CsvFile(BaseModel):
    filename: str
    text: str


def slug(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-") or "event"


def export_csv(event_name: str, races: Iterable[Race], kind: ExportKind, now_ms: int) -> CsvFile:
    races = [race for race in races if race.status is RaceStatus.SUBMITTED]
    text = csv_export.all_laps_csv(races) if kind is ExportKind.LAPS else csv_export.racer_summary_csv(
        summarise_event(races))
    day = datetime.fromtimestamp(now_ms / 1000, tz=UTC).date().isoformat()
    return CsvFile(filename=f"{slug(event_name)}-{kind.value}-{day}.csv", text=text)
