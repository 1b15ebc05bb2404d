"""A racer's summary on one track over all their SUBMITTED races: the numbers the leaderboard and exports show.

Unlike DREM, a racer whose laps are all invalid still gets a summary: the time fields are None instead of a crash.
"""
from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable

from pydantic import BaseModel, ConfigDict, Field

from drem_leaderboard.averages import AverageWindow, fastest_window, rounded_mean_ms
from drem_leaderboard.models import Race, RaceStatus


class LapCountResult(BaseModel):
    """A race's result under LAP_COUNT: valid laps, and the race clock when the last of them was completed."""

    model_config = ConfigDict(frozen=True)

    race_id: str
    valid_laps: int = Field(ge=1)
    elapsed_ms: int = Field(ge=0, description="sum of every lap (valid or not) up to the last counted valid lap")
    achieved_at_ms: int


class RaceSummary(BaseModel):
    model_config = ConfigDict(frozen=True)

    event_id: str
    track_id: str
    racer_sub: str
    username: str
    raced_by_proxy: bool = Field(description="at least one of these races was driven by a staff member")
    races: int
    total_laps: int
    valid_laps: int
    invalid_laps: int
    total_resets: int
    fastest_lap_ms: int | None = None
    fastest_lap_at_ms: int | None = None
    fastest_average: AverageWindow | None = None
    fastest_average_race_id: str | None = None
    average_lap_ms: int | None = Field(default=None, description="mean of the valid laps, rounded to whole ms")
    lap_completion_pct: float | None = Field(
        default=None, description="valid / total laps × 100 to one decimal; None when there are no laps"
    )
    laps_per_attempt: float = Field(description="total laps / races, one decimal")
    most_consecutive_valid_laps: int = Field(description="longest run of valid laps inside one race")
    best_lap_count: LapCountResult | None = None


def summarise_racer(races: Iterable[Race]) -> RaceSummary | None:
    """Summary of one racer on one track; None when none of the races has been submitted."""
    submitted = sorted(
        (race for race in races if race.status is RaceStatus.SUBMITTED),
        key=lambda race: (race.submitted_at_ms or race.created_at_ms, race.race_id),
    )
    if not submitted:
        return None
    keys = {(race.event_id, race.track_id, race.racer.sub) for race in submitted}
    if len(keys) > 1:
        raise ValueError("a race summary covers one racer on one track of one event")
    laps = [lap for race in submitted for lap in race.laps]
    valid = [lap for lap in laps if lap.is_valid]
    fastest = min(valid, key=lambda lap: (lap.time_ms, lap.captured_at_ms), default=None)
    best_windows = [(w, race.race_id) for race in submitted if (w := fastest_window(race.average_windows))]
    best_window = fastest_window([w for w, _ in best_windows])
    latest = submitted[-1]
    return RaceSummary(
        event_id=latest.event_id,
        track_id=latest.track_id,
        racer_sub=latest.racer.sub,
        username=latest.racer.username,
        raced_by_proxy=any(race.raced_by_proxy for race in submitted),
        races=len(submitted),
        total_laps=len(laps),
        valid_laps=len(valid),
        invalid_laps=len(laps) - len(valid),
        total_resets=sum(lap.resets for lap in laps),
        fastest_lap_ms=fastest.time_ms if fastest else None,
        fastest_lap_at_ms=fastest.captured_at_ms if fastest else None,
        fastest_average=best_window,
        fastest_average_race_id=next((rid for w, rid in best_windows if w == best_window), None),
        average_lap_ms=rounded_mean_ms([lap.time_ms for lap in valid]) if valid else None,
        lap_completion_pct=round(100 * len(valid) / len(laps), 1) if laps else None,
        laps_per_attempt=round(len(laps) / len(submitted), 1),
        most_consecutive_valid_laps=max(_longest_valid_run(race) for race in submitted),
        best_lap_count=_best_lap_count(submitted),
    )


def summarise_event(races: Iterable[Race]) -> list[RaceSummary]:
    """One summary per (track, racer) that has at least one submitted race, ordered by track then racer."""
    groups: dict[tuple[str, str], list[Race]] = defaultdict(list)
    for race in races:
        groups[(race.track_id, race.racer.sub)].append(race)
    summaries = (summarise_racer(group) for _, group in sorted(groups.items()))
    return [summary for summary in summaries if summary is not None]


def _longest_valid_run(race: Race) -> int:
    longest = current = 0
    for lap in sorted(race.laps, key=lambda lap: lap.lap_id):
        current = current + 1 if lap.is_valid else 0
        longest = max(longest, current)
    return longest


def lap_count_result(race: Race) -> LapCountResult | None:
    ordered = sorted(race.laps, key=lambda lap: lap.lap_id)
    valid_positions = [i for i, lap in enumerate(ordered) if lap.is_valid]
    target = race.config.lap_count_target
    if target is not None:
        valid_positions = valid_positions[:target]
    if not valid_positions:
        return None
    last = valid_positions[-1]
    return LapCountResult(
        race_id=race.race_id,
        valid_laps=len(valid_positions),
        elapsed_ms=sum(lap.time_ms for lap in ordered[: last + 1]),
        achieved_at_ms=ordered[last].captured_at_ms,
    )


def _best_lap_count(races: list[Race]) -> LapCountResult | None:
    results = [result for race in races if (result := lap_count_result(race))]
    return min(results, key=lambda r: (-r.valid_laps, r.elapsed_ms, r.achieved_at_ms), default=None)
