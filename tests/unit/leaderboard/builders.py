"""Small builders for races in a known state, so each test reads as the story it checks."""
from __future__ import annotations

from drem_leaderboard import commands as c
from drem_leaderboard.models import Lap, LapSource, Race, RaceConfig, Racer, RaceStatus, new_race
from drem_leaderboard.race_machine import apply

T0 = 1_700_000_000_000  # server clock at race creation


def make_race(
    config: RaceConfig | None = None,
    *,
    race_id: str = "race-1",
    track_id: str = "1",
    sub: str = "sub-alice",
    username: str = "alice",
    raced_by_proxy: bool = False,
) -> Race:
    return new_race(
        race_id=race_id,
        event_id="event-1",
        track_id=track_id,
        racer=Racer(sub=sub, username=username),
        config=config or RaceConfig(),
        now_ms=T0,
        raced_by_proxy=raced_by_proxy,
    )


def run(race: Race, *steps: tuple[c.RaceCommand, int]) -> Race:
    for command, now_ms in steps:
        race, _ = apply(race, command, now_ms)
    return race


def submitted_race(
    lap_times_ms: list[int],
    *,
    valid: list[bool] | None = None,
    resets: list[int] | None = None,
    race_id: str = "race-1",
    track_id: str = "1",
    sub: str = "sub-alice",
    username: str = "alice",
    finished_at_ms: int = T0,
    config: RaceConfig | None = None,
    raced_by_proxy: bool = False,
) -> Race:
    """A SUBMITTED race with the given laps; lap i ends at finished_at_ms + cumulative time."""
    valid = valid or [True] * len(lap_times_ms)
    resets = resets or [0] * len(lap_times_ms)
    laps: list[Lap] = []
    clock = finished_at_ms
    for i, time_ms in enumerate(lap_times_ms):
        clock += time_ms
        laps.append(
            Lap(
                lap_id=i,
                time_ms=time_ms,
                resets=resets[i],
                is_valid=valid[i],
                source=LapSource.MANUAL,
                captured_at_ms=clock,
            )
        )
    race = make_race(
        config, race_id=race_id, track_id=track_id, sub=sub, username=username, raced_by_proxy=raced_by_proxy
    )
    return race.model_copy(
        update={"laps": tuple(laps), "status": RaceStatus.SUBMITTED, "submitted_at_ms": clock + 1}
    )
