"""Timing-strip crossings from a timer device: debounce, "both strips are one lap", and what a crossing does.

A device sends ``{timestamp_ms (device clock), sensor (gpio), idempotency_key}``. ``decide`` classifies a new event
without changing anything; ``handle_strip_event`` applies it. Devices retry, so the caller stores each outcome under its
idempotency key and, for a key it has seen, calls ``replay_outcome`` instead: the race is untouched and the device gets
the answer it got the first time.
"""
from __future__ import annotations

from enum import StrEnum

from pydantic import BaseModel, ConfigDict, Field

from drem_leaderboard.models import TERMINAL_STATUSES, Lap, LapSource, Race, RaceStatus
from drem_leaderboard.race_clock import running_time_ms
from drem_leaderboard.race_machine import begin_running, note_expiry, record_lap, resume_running

# 2100-01-01T00:00:00Z. A device clock beyond it is a fault or an attack: 10**18 once froze a race (every later,
# true crossing read as out of order) and 10**30 overflowed storage. A Pi without network time may start near 1970,
# so there is no lower bound beyond 0.
MAX_DEVICE_TIMESTAMP_MS = 4_102_444_800_000


class StripEvent(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    timestamp_ms: int = Field(ge=0, le=MAX_DEVICE_TIMESTAMP_MS, description="device clock, ms since the epoch")
    sensor: int = Field(ge=0, le=1000, description="GPIO number of the strip, e.g. 17 or 27")
    idempotency_key: str = Field(min_length=1, max_length=200)


class StripAction(StrEnum):
    START = "start"  # first crossing of a READY race: starts it and seeds the lap
    RESUME = "resume"  # crossing while PAUSED: resumes and seeds a fresh lap
    SEED = "seed"  # crossing while RUNNING with no seed yet: the lap begins at the line
    LAP = "lap"  # crossing that ends a lap
    IGNORE = "ignore"


class IgnoreReason(StrEnum):
    RACE_NOT_LIVE = "race_not_live"
    OUT_OF_ORDER = "out_of_order"
    SENSOR_DEBOUNCE = "sensor_debounce"
    SAME_CROSSING = "same_crossing"
    LAP_TOO_SHORT = "lap_too_short"


class StripDecision(BaseModel):
    model_config = ConfigDict(frozen=True)

    action: StripAction
    reason: IgnoreReason | None = None
    message: str
    lap_time_ms: int | None = None
    sensor_fired: bool = Field(
        default=False, description="the sensor produced a fresh trigger (outside its own debounce window)"
    )


class StripOutcome(BaseModel):
    """What the caller stores under the idempotency key and returns to the device."""

    model_config = ConfigDict(frozen=True)

    idempotency_key: str
    action: StripAction
    reason: IgnoreReason | None = None
    message: str
    lap: Lap | None = None
    status: RaceStatus
    race_ended: bool = False
    race_version: int
    replayed: bool = False


def decide(race: Race, event: StripEvent) -> StripDecision:
    """Classify a crossing the race has not seen before; pure."""
    config = race.config
    if race.status is RaceStatus.OVER or race.status in TERMINAL_STATUSES:
        return _ignore(IgnoreReason.RACE_NOT_LIVE, f"crossing ignored: the race is {race.status.value.lower()}")
    ts = event.timestamp_ms
    last_for_sensor = race.sensor_last_ts_ms.get(event.sensor)
    if (last_for_sensor is not None and ts < last_for_sensor) or (
        race.last_crossing_ts_ms is not None and ts < race.last_crossing_ts_ms
    ):
        return _ignore(IgnoreReason.OUT_OF_ORDER, "crossing ignored: it is older than one already counted")
    if last_for_sensor is not None and ts - last_for_sensor < config.debounce_ms:
        return _ignore(
            IgnoreReason.SENSOR_DEBOUNCE,
            f"crossing ignored: sensor {event.sensor} fired {ts - last_for_sensor} ms after its last trigger "
            f"(debounce {config.debounce_ms} ms)",
        )
    if race.last_crossing_ts_ms is not None and ts - race.last_crossing_ts_ms < config.min_lap_ms:
        return _ignore(
            IgnoreReason.SAME_CROSSING,
            f"crossing ignored: {ts - race.last_crossing_ts_ms} ms after the last crossing, "
            f"under the {config.min_lap_ms} ms minimum lap (the car touched both strips)",
            sensor_fired=True,
        )
    if race.status is RaceStatus.READY:
        return StripDecision(action=StripAction.START, message="race started by the timing strip", sensor_fired=True)
    if race.status is RaceStatus.PAUSED:
        return StripDecision(action=StripAction.RESUME, message="race resumed by the timing strip", sensor_fired=True)
    if race.lap_seed_ts_ms is None:
        return StripDecision(action=StripAction.SEED, message="lap timing started at the line", sensor_fired=True)
    lap_time = ts - race.lap_seed_ts_ms
    if lap_time < config.min_lap_ms:
        return _ignore(
            IgnoreReason.LAP_TOO_SHORT,
            f"crossing ignored: a {lap_time} ms lap is under the {config.min_lap_ms} ms minimum",
            sensor_fired=True,
        )
    return StripDecision(action=StripAction.LAP, message=f"lap of {lap_time} ms", lap_time_ms=lap_time,
                         sensor_fired=True)


def _ignore(reason: IgnoreReason, message: str, *, sensor_fired: bool = False) -> StripDecision:
    return StripDecision(action=StripAction.IGNORE, reason=reason, message=message, sensor_fired=sensor_fired)


def handle_strip_event(race: Race, event: StripEvent, now_ms: int) -> tuple[Race, StripOutcome]:
    """Apply a new crossing at server time ``now_ms``. Never raises for a rule: an unusable crossing is ignored."""
    decision = decide(race, event)
    after = note_expiry(race, now_ms)
    if decision.sensor_fired:
        after = after.model_copy(update={"sensor_last_ts_ms": {**after.sensor_last_ts_ms,
                                                               event.sensor: event.timestamp_ms}})
    lap: Lap | None = None
    ts = event.timestamp_ms
    if decision.action is StripAction.START:
        after = _seed(begin_running(after, now_ms), ts, now_ms)
    elif decision.action is StripAction.RESUME:
        after = _seed(resume_running(after, now_ms), ts, now_ms)
    elif decision.action is StripAction.SEED:
        after = _seed(after, ts, now_ms)
    elif decision.action is StripAction.LAP:
        assert decision.lap_time_ms is not None
        after, lap = record_lap(after, now_ms, time_ms=decision.lap_time_ms, source=LapSource.TIMER, device_ts_ms=ts)
        after = after.model_copy(update={"last_crossing_ts_ms": ts})
    if after != race:
        after = after.model_copy(update={"version": race.version + 1})
    return after, StripOutcome(
        idempotency_key=event.idempotency_key,
        action=decision.action,
        reason=decision.reason,
        message=decision.message,
        lap=lap,
        status=after.status,
        race_ended=race.status is not RaceStatus.OVER and after.status is RaceStatus.OVER,
        race_version=after.version,
    )


def _seed(race: Race, ts: int, now_ms: int) -> Race:
    """The lap begins at the line: both its device timestamp and the race-clock reading restart here."""
    return race.model_copy(
        update={
            "lap_seed_ts_ms": ts,
            "last_crossing_ts_ms": ts,
            "lap_started_running_ms": running_time_ms(race, now_ms),
        }
    )


def replay_outcome(stored: StripOutcome) -> StripOutcome:
    """The answer for a repeated idempotency key: the original outcome, marked as a replay."""
    return stored.model_copy(update={"replayed": True})
