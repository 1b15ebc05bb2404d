"""Clock readings derived from a race and the server time; nothing here changes a race."""
from __future__ import annotations

from drem_leaderboard.models import Race, RaceStatus


def running_time_ms(race: Race, now_ms: int) -> int:
    """Race-clock time: the time the race has spent RUNNING up to ``now_ms``."""
    if race.status is RaceStatus.RUNNING and race.running_since_ms is not None:
        # A server clock that steps backwards must never make the race clock run backwards.
        return race.running_ms + max(0, now_ms - race.running_since_ms)
    return race.running_ms


def current_lap_ms(race: Race, now_ms: int) -> int:
    return max(0, running_time_ms(race, now_ms) - race.lap_started_running_ms)


def race_time_left_ms(race: Race, now_ms: int) -> int:
    return max(0, race.config.race_time_ms - running_time_ms(race, now_ms))


def time_is_up(race: Race, now_ms: int) -> bool:
    return race.time_expired or (
        race.status is RaceStatus.RUNNING and running_time_ms(race, now_ms) >= race.config.race_time_ms
    )
