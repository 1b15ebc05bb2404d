"""The race's data: its frozen configuration, laps, status and the plain-number clocks the state machine keeps.

Every model is immutable so the pure functions in this package can never change a race a caller still holds.
Times are integer milliseconds; ``*_at_ms`` values are the server clock, ``*_ts_ms`` values the timer device's clock.
"""
from __future__ import annotations

from enum import StrEnum
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, computed_field, field_validator, model_validator

from drem_leaderboard.averages import AverageWindow, average_windows, fastest_window

__all__ = [
    "DREM_UNLIMITED", "AverageWindow", "Lap", "LapSource", "Race", "RaceConfig", "RaceStatus", "Racer",
    "RankingMethod", "TERMINAL_STATUSES", "TrackType", "new_race",
]

# DREM stores "unlimited" as 9999 for both resets per lap and runs per racer.
DREM_UNLIMITED = 9999


class RankingMethod(StrEnum):
    BEST_LAP_TIME = "BEST_LAP_TIME"
    BEST_AVERAGE_LAP_TIME_X_LAP = "BEST_AVERAGE_LAP_TIME_X_LAP"
    LAP_COUNT = "LAP_COUNT"


class TrackType(StrEnum):
    REINVENT_2018 = "REINVENT_2018"
    REINVENT_2019 = "REINVENT_2019"
    REINVENT_2022 = "REINVENT_2022"
    REINVENT_2023 = "REINVENT_2023"
    FOREVER_RACEWAY = "FOREVER_RACEWAY"
    SUMMIT_SPEEDWAY = "SUMMIT_SPEEDWAY"
    ATOZ_SPEEDWAY = "ATOZ_SPEEDWAY"
    OTHER = "OTHER"


def _unlimited_as_none(value: Any) -> Any:
    if value is None:
        return None
    if isinstance(value, str) and value.strip().isdigit():
        value = int(value.strip())
    return None if value == DREM_UNLIMITED else value


class RaceConfig(BaseModel):
    """The rules one race runs under; copied from the event when the race is created and frozen from then on."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    race_time_min: int = Field(default=2, ge=1, le=10)
    resets_per_lap: int | None = Field(default=None, ge=0, le=10, description="None = unlimited")
    track_type: TrackType = TrackType.REINVENT_2018
    ranking_method: RankingMethod = RankingMethod.BEST_LAP_TIME
    lap_count_target: int | None = Field(
        default=None, ge=1, le=1000, description="LAP_COUNT only: the race ends once this many valid laps are done"
    )
    max_runs_per_racer: int | None = Field(default=3, ge=1, le=5, description="None = unlimited")
    average_window: int = Field(default=3, ge=3, le=7)
    debounce_ms: int = Field(default=2000, ge=0, le=60_000)
    min_lap_ms: int = Field(default=3000, ge=0, le=600_000)

    @field_validator("resets_per_lap", "max_runs_per_racer", mode="before")
    @classmethod
    def _accept_drem_unlimited(cls, value: Any) -> Any:
        return _unlimited_as_none(value)

    @model_validator(mode="after")
    def _lap_target_only_for_lap_count(self) -> RaceConfig:
        if self.lap_count_target is not None and self.ranking_method is not RankingMethod.LAP_COUNT:
            raise ValueError("lap_count_target only applies to the LAP_COUNT ranking method")
        return self

    @property
    def race_time_ms(self) -> int:
        return self.race_time_min * 60_000

    def runs_left(self, races_done: int) -> int | None:
        """Races the racer may still start (None = unlimited). DREM only displays this; the race service enforces it."""
        if self.max_runs_per_racer is None:
            return None
        return max(0, self.max_runs_per_racer - races_done)


class LapSource(StrEnum):
    MANUAL = "manual"
    TIMER = "timer"
    DNF = "dnf"


class Lap(BaseModel):
    model_config = ConfigDict(frozen=True)

    lap_id: int = Field(ge=0, description="0-based position in the race")
    time_ms: int = Field(ge=0)
    resets: int = Field(default=0, ge=0)
    is_valid: bool
    source: LapSource
    car: str | None = None
    device_ts_ms: int | None = Field(default=None, description="timer device clock when the lap ended")
    captured_at_ms: int = Field(ge=0, description="server clock when the lap ended; breaks ranking ties")


class RaceStatus(StrEnum):
    READY = "READY"
    RUNNING = "RUNNING"
    PAUSED = "PAUSED"
    OVER = "OVER"
    SUBMITTED = "SUBMITTED"
    DISCARDED = "DISCARDED"


TERMINAL_STATUSES = frozenset({RaceStatus.SUBMITTED, RaceStatus.DISCARDED})


class Racer(BaseModel):
    model_config = ConfigDict(frozen=True)

    sub: str = Field(min_length=1, description="Cognito user id")
    username: str = Field(min_length=1)


class Race(BaseModel):
    """One racer's attempt on one track.

    Clocks: the race clock (``running``) only advances while RUNNING. ``running_ms`` holds the time banked before the
    current running stretch, which began at server time ``running_since_ms``. ``lap_started_running_ms`` is the race
    clock reading at which the current lap began. ``lap_seed_ts_ms`` is the timer-device time at which the current lap
    began (None until a strip crossing seeds it), so a timer lap is the difference of two device timestamps.
    """

    model_config = ConfigDict(frozen=True)

    race_id: str = Field(min_length=1)
    event_id: str = Field(min_length=1)
    track_id: str = Field(min_length=1)
    racer: Racer
    raced_by_proxy: bool = False
    config: RaceConfig
    status: RaceStatus = RaceStatus.READY
    laps: tuple[Lap, ...] = ()
    current_lap_resets: int = Field(default=0, ge=0)
    car: str | None = None
    created_at_ms: int = Field(ge=0)
    started_at_ms: int | None = None
    ended_at_ms: int | None = None
    submitted_at_ms: int | None = None
    running_ms: int = Field(default=0, ge=0)
    running_since_ms: int | None = None
    paused_at_ms: int | None = None
    lap_started_running_ms: int = Field(default=0, ge=0)
    time_expired: bool = False
    sensor_last_ts_ms: dict[int, int] = Field(default_factory=dict)
    last_crossing_ts_ms: int | None = None
    lap_seed_ts_ms: int | None = None
    version: int = Field(default=0, ge=0)

    @computed_field  # type: ignore[prop-decorator]
    @property
    def average_windows(self) -> list[AverageWindow]:
        return average_windows(self.laps, self.config.average_window)

    @property
    def valid_laps(self) -> list[Lap]:
        return [lap for lap in self.laps if lap.is_valid]

    @property
    def fastest_valid_lap(self) -> Lap | None:
        return min(self.valid_laps, key=lambda lap: (lap.time_ms, lap.lap_id), default=None)

    @property
    def fastest_average(self) -> AverageWindow | None:
        return fastest_window(self.average_windows)


def new_race(
    *,
    race_id: str,
    event_id: str,
    track_id: str,
    racer: Racer,
    config: RaceConfig,
    now_ms: int,
    raced_by_proxy: bool = False,
    car: str | None = None,
) -> Race:
    return Race(
        race_id=race_id,
        event_id=event_id,
        track_id=track_id,
        racer=racer,
        raced_by_proxy=raced_by_proxy,
        config=config,
        car=car,
        created_at_ms=now_ms,
    )
