"""DREM's two CSV exports: every lap, and one summary row per racer and track.

Text a user typed (usernames, ids, track names, car names) is neutralised against spreadsheet formula injection: a cell
starting with = + - @ (or a tab/carriage return, which some spreadsheets also strip) gets a leading apostrophe.
"""
from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Sequence
from datetime import UTC, datetime

from drem_leaderboard.models import Race
from drem_leaderboard.summary import RaceSummary

ALL_LAPS_COLUMNS = (
    "Race ID",
    "Username",
    "User ID",
    "Track",
    "Raced By Proxy",
    "Race Date",
    "Lap #",
    "Lap Time (ms)",
    "Lap Time (s)",
    "Resets",
    "Valid",
)
RACER_SUMMARY_COLUMNS = (
    "Username",
    "User ID",
    "Track",
    "Races",
    "Total laps",
    "Valid laps",
    "Invalid laps",
    "Fastest",
    "Avg",
    "Total resets",
    "Completion %",
)
_FORMULA_PREFIXES = ("=", "+", "-", "@", "\t", "\r")


def safe_text(value: str) -> str:
    return "'" + value if value.startswith(_FORMULA_PREFIXES) else value


def _seconds(ms: int | None) -> str:
    return "" if ms is None else f"{ms / 1000:.3f}"


def _iso_utc(ms: int) -> str:
    return datetime.fromtimestamp(ms / 1000, tz=UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def _yes_no(flag: bool) -> str:
    return "true" if flag else "false"


def _write(columns: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\r\n")
    writer.writerow(columns)
    writer.writerows(rows)
    return buffer.getvalue()


def all_laps_csv(races: Iterable[Race]) -> str:
    """One row per lap, races in date order; Race Date is when the race was submitted (else created), UTC."""
    ordered = sorted(races, key=lambda race: (race.submitted_at_ms or race.created_at_ms, race.race_id))
    rows = (
        (
            race.race_id,
            safe_text(race.racer.username),
            safe_text(race.racer.sub),
            safe_text(race.track_id),
            _yes_no(race.raced_by_proxy),
            _iso_utc(race.submitted_at_ms or race.created_at_ms),
            str(lap.lap_id + 1),
            str(lap.time_ms),
            _seconds(lap.time_ms),
            str(lap.resets),
            _yes_no(lap.is_valid),
        )
        for race in ordered
        for lap in sorted(race.laps, key=lambda lap: lap.lap_id)
    )
    return _write(ALL_LAPS_COLUMNS, rows)


def racer_summary_csv(summaries: Iterable[RaceSummary]) -> str:
    """One row per racer and track; Fastest and Avg in seconds (3 decimals), blank when there is no valid lap."""
    rows = (
        (
            safe_text(s.username),
            safe_text(s.racer_sub),
            safe_text(s.track_id),
            str(s.races),
            str(s.total_laps),
            str(s.valid_laps),
            str(s.invalid_laps),
            _seconds(s.fastest_lap_ms),
            _seconds(s.average_lap_ms),
            str(s.total_resets),
            "" if s.lap_completion_pct is None else f"{s.lap_completion_pct:.1f}",
        )
        for s in sorted(summaries, key=lambda s: (s.track_id, s.username.casefold(), s.racer_sub))
    )
    return _write(RACER_SUMMARY_COLUMNS, rows)
