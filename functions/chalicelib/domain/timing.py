"""Timing-strip posts from timer devices (and cars with a strip): which race they belong to, and exactly-once laps.

A post names the event and track; the device must be in that track's fleet. The crossing is applied to the track's
live race with `drem_leaderboard.timer_input.handle_strip_event`. Devices retry, so the answer is stored under
`(device, idempotency_key)` in the same transaction as the race change, BEFORE it is returned; a repeated key gets
the stored answer back (`replayed: true`) and never a second lap. A replay also finishes any board publish a crash
left pending (the race write and its publish intent are stored together, the board after), so a retry of a post whose
answer was lost brings the board up to date.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.auth.principals import Device
from chalicelib.domain.errors import DremError, Forbidden, MaybeStored
from chalicelib.domain.races import RaceRecord, RaceService, with_retries
from drem_leaderboard.models import Lap
from drem_leaderboard.timer_input import StripEvent, handle_strip_event


class StripPost(BaseModel):
    model_config = ConfigDict(extra="forbid")
    event_id: str = Field(min_length=1, max_length=64)
    track_id: str = Field(min_length=1, max_length=32)
    timestamp_ms: int = Field(ge=0, description="device clock, ms since the epoch")
    sensor: int = Field(ge=0, le=1000)
    idempotency_key: str = Field(min_length=1, max_length=200)


class StripAnswer(BaseModel):
    """What the device gets back (and what is stored under its idempotency key)."""
    idempotency_key: str
    action: str
    reason: str | None = None
    message: str
    race_id: str | None = None
    lap: Lap | None = None
    status: str | None = None
    race_ended: bool = False
    race_version: int | None = None
    replayed: bool = False


class OutcomeStore(Protocol):
    def get_outcome(self, device_id: str, key: str) -> str | None: ...
    def live_race_id(self, event_id: str, track_id: str) -> str | None: ...
    def save_with_outcome(self, record: RaceRecord | None, expected_version: int | None, device_id: str, key: str,
                          outcome_json: str) -> bool: ...


class DeviceFleets(Protocol):
    def fleet_of(self, device_id: str) -> str | None: ...


class TimingService:
    def __init__(self, races: RaceService, outcomes: OutcomeStore, fleets: DeviceFleets,
                 clock_ms: Callable[[], int]) -> None:
        self._races = races
        self._outcomes = outcomes
        self._fleets = fleets
        self._clock_ms = clock_ms

    def strip_event(self, device: Device, post: StripPost) -> StripAnswer:
        event = self._races.event(post.event_id)
        fleet = event.track(post.track_id).fleet_id
        if fleet is None or self._fleets.fleet_of(device.device_id) != fleet:
            raise Forbidden(f"Device {device.device_id} is not in the fleet of track {post.track_id}.")
        stored = self._replay(device.device_id, post.idempotency_key)
        if stored is not None:
            self._catch_up_boards()
            return stored
        crossing = StripEvent(timestamp_ms=post.timestamp_ms, sensor=post.sensor, idempotency_key=post.idempotency_key)

        def attempt() -> tuple[StripAnswer, RaceRecord | None, int]:
            now = self._clock_ms()
            race_id = self._outcomes.live_race_id(post.event_id, post.track_id)
            if race_id is None:
                answer = StripAnswer(idempotency_key=post.idempotency_key, action="ignore", reason="no_live_race",
                                     message=f"crossing ignored: no race is live on track {post.track_id}")
                return self._keep(device, answer, None, None), None, now
            record = self._races.record(post.event_id, race_id)
            after, outcome = handle_strip_event(record.race, crossing, now)
            answer = StripAnswer(**outcome.model_dump(), race_id=race_id)
            changed = after != record.race
            updated = record.model_copy(update={"race": after}) if changed else None
            kept = self._keep(device, answer, updated, record.race.version if changed else None)
            return kept, (updated if kept is answer else None), now

        try:
            answer, updated, now = with_retries(attempt)
        except MaybeStored as exc:
            raise MaybeStored("Storage stopped answering while this crossing was being saved, so it may or may not "
                              "have been stored. Post it again with the same idempotency_key once storage is back: a "
                              "repeated key is never counted twice.") from exc
        if updated is not None:
            self._races.publish(event, updated.race, now)
        return answer

    def _keep(self, device: Device, answer: StripAnswer, record: RaceRecord | None,
              expected_version: int | None) -> StripAnswer:
        """Store the answer (with the race change) before returning it; if a concurrent retry stored one first,
        return that one instead."""
        if self._outcomes.save_with_outcome(record, expected_version, device.device_id, answer.idempotency_key,
                                            answer.model_dump_json()):
            return answer
        replay = self._replay(device.device_id, answer.idempotency_key)
        assert replay is not None  # save_with_outcome said it exists
        return replay

    def _catch_up_boards(self) -> None:
        try:
            self._races.complete_pending_publishes()
        except DremError:
            pass  # storage is struggling; the stored answer is still true, and the intent stays for the next one

    def _replay(self, device_id: str, key: str) -> StripAnswer | None:
        stored = self._outcomes.get_outcome(device_id, key)
        if stored is None:
            return None
        return StripAnswer.model_validate_json(stored).model_copy(update={"replayed": True})
