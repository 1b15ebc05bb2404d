"""What people read instead of enum values, and lap times in one format (`0:08.838`) on every page.

`label(value)` is the Jinja filter `label`: an event type, track type, ranking method, race or model status becomes
the words DREM's console shows for it (events.tracks.* etc. in DREM's English catalogue); an unknown value is
de-shouted ("SOME_VALUE" → "Some value") rather than shown raw. `laptime(ms)` is the filter `laptime`.
"""
from __future__ import annotations

from enum import Enum
from typing import Any

LABELS: dict[str, str] = {
    # event types
    "PRIVATE_WORKSHOP": "Private workshop", "PRIVATE_TRACK_RACE": "Private track race",
    "OFFICIAL_WORKSHOP": "Official workshop", "OFFICIAL_TRACK_RACE": "Official track race",
    "AWS_SUMMIT": "AWS Summit", "TEST_EVENT": "Test event", "OTHER": "Other",
    # track types (DREM's list). Forever Raceway (`2024_reinvent_champ`) is the re:Invent 2024 championship track and
    # the last official one (the 2025 virtual races used it too), so its label says the year: "stops at 2023" was only
    # the label hiding it.
    "REINVENT_2018": "re:Invent 2018", "REINVENT_2019": "re:Invent 2019", "REINVENT_2022": "re:Invent 2022",
    "REINVENT_2023": "re:Invent 2023", "FOREVER_RACEWAY": "re:Invent 2024 · Forever Raceway",
    "ATOZ_SPEEDWAY": "A to Z Speedway", "SUMMIT_SPEEDWAY": "Summit Speedway 2022",
    # ranking methods
    "BEST_LAP_TIME": "Fastest lap", "BEST_AVERAGE_LAP_TIME_X_LAP": "Fastest average over X laps",
    "LAP_COUNT": "Most laps",
    # race statuses
    "READY": "Ready", "RUNNING": "Running", "PAUSED": "Paused", "OVER": "Time is up", "SUBMITTED": "Submitted",
    "DISCARDED": "Discarded",
    # account statuses (Cognito's), on the Users page
    "UNCONFIRMED": "Waiting for the emailed code", "FORCE_CHANGE_PASSWORD": "Temporary password, not signed in yet",
    "RESET_REQUIRED": "Password reset required",
    # model statuses
    "UPLOADED": "Checking…", "AVAILABLE": "Ready to race", "NOT_VALID": "Not valid", "QUARANTINED": "Quarantined",
    "DELETED": "Deleted",
    # model sensors and training algorithms (the console's model_metadata.json values)
    "FRONT_FACING_CAMERA": "Front camera", "STEREO_CAMERAS": "Stereo cameras", "LIDAR": "LiDAR",
    "SECTOR_LIDAR": "Sector LiDAR", "DISCRETIZED_SECTOR_LIDAR": "Discretised sector LiDAR",
    "clipped_ppo": "PPO", "sac": "SAC", "behaviour_cloning": "Behaviour cloning",
}


def label(value: Any) -> str:
    raw = value.value if isinstance(value, Enum) else "" if value is None else str(value)
    return LABELS.get(raw) or raw.replace("_", " ").capitalize()


def options(values: Any) -> list[tuple[str, str]]:
    """(value, label) pairs for a <select> of an enum (or of plain values)."""
    return [(v.value if isinstance(v, Enum) else str(v), label(v)) for v in values]


def laptime(ms: int | float | None, missing: str = "–") -> str:
    """1:02.345, 0:08.838; None → `missing`."""
    if ms is None:
        return missing
    minutes, rest = divmod(max(0, int(ms)), 60_000)
    return f"{minutes}:{rest // 1000:02d}.{rest % 1000:03d}"
