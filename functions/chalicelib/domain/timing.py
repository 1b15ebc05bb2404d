"""Timing-strip posts from timer devices (and cars with a strip): which race they belong to, and exactly-once laps.

A post names the event and track. Who may time a race (docs/racing.md, "Who may post crossings"):

* the device must be in that track's fleet;
* a car only times the race it is the car of (`race.car` is its device id or hostname);
* the first device whose crossing counts is the race's clock (`RaceRecord.timed_by`); any other device is refused,
  because a lap is the difference of two timestamps of one device clock.

The crossing is applied to the track's live race with `drem_leaderboard.timer_input.handle_strip_event`. Devices
retry, so the answer is stored under `(device, idempotency_key)` in the same transaction as the race change, BEFORE it
is returned; a repeated key gets the stored answer back (`replayed: true`) and never a second lap. A replay also
finishes any board publish a crash
left pending (the race write and its publish intent are stored together, the board after), so a retry of a post whose
answer was lost brings the board up to date.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.core.errors import DremError, Forbidden, MaybeStored, NotFound
from chalicelib.core.principals import Device, RegistryEntry
from chalicelib.domain.devices import DeviceKind, DeviceRecord
from chalicelib.domain.race_writes import with_retries
from chalicelib.domain.races import EventSource, RaceRecord, RaceService
from drem_leaderboard.models import Lap
from drem_leaderboard.timer_input import MAX_DEVICE_TIMESTAMP_MS, StripEvent, handle_strip_event


class StripPost(BaseModel):
    model_config = ConfigDict(extra="forbid")
    event_id: str = Field(min_length=1, max_length=64)
    track_id: str = Field(min_length=1, max_length=32)
    timestamp_ms: int = Field(ge=0, le=MAX_DEVICE_TIMESTAMP_MS,
                              description="device clock, ms since the epoch (before 2100-01-01)")
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
    def get(self, event_id: str, race_id: str) -> RaceRecord | None: ...
    def get_outcome(self, device_id: str, key: str) -> str | None: ...
    def live_race_id(self, event_id: str, track_id: str) -> str | None: ...
    def save_with_outcome(self, record: RaceRecord | None, expected_version: int | None, device_id: str, key: str,
                          outcome_json: str) -> bool: ...


class DeviceDirectory(Protocol):
    def get_device(self, device_id: str) -> DeviceRecord | None: ...


class TimingService:
    def __init__(self, races: RaceService, outcomes: OutcomeStore, devices: DeviceDirectory,
                 clock_ms: Callable[[], int], events: EventSource) -> None:
        """`races` is entered once per crossing, to publish the change: the event, the race and its write come from
        the stores directly."""
        self._races = races
        self._events = events
        self._outcomes = outcomes
        self._devices = devices
        self._clock_ms = clock_ms

    def strip_event(self, device: Device, post: StripPost) -> StripAnswer:
        event = self._events.get(post.event_id)
        if event is None:
            raise NotFound(f"There is no event {post.event_id}.", field="event_id")
        fleet = event.track(post.track_id).fleet_id
        registered = device.registry or self._registry_entry(device.device_id)
        if fleet is None or registered is None or registered.fleet_id != fleet:
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
            record = self._outcomes.get(post.event_id, race_id)
            if record is None:
                raise NotFound(f"Event {post.event_id} has no race {race_id}.", field="race_id")
            _check_may_time(device, registered, record)
            after, outcome = handle_strip_event(record.race, crossing, now)
            answer = StripAnswer(**outcome.model_dump(), race_id=race_id)
            changed = after != record.race
            updated = record.model_copy(update={"race": after, "timed_by": record.timed_by or device.device_id}) \
                if changed else None
            kept = self._keep(device, answer, updated, record.race.version if changed else None)
            return kept, (updated if kept is answer else None), now

        try:
            answer, updated, now = with_retries(attempt)
        except MaybeStored as exc:
            raise MaybeStored("Storage stopped answering while this crossing was being saved, so it may or may not "
                              "have been stored. Post it again with the same idempotency_key once storage is back: a "
                              "repeated key is never counted twice.") from exc
        if updated is not None:
            self._races.publish(event, updated.race, now, live_race_id=updated.race.race_id)
        return answer

    def _registry_entry(self, device_id: str) -> RegistryEntry | None:
        """The registry's entry for a device principal that does not carry it (one made outside a credential check)."""
        record = self._devices.get_device(device_id)
        return None if record is None else RegistryEntry(hostname=record.hostname, fleet_id=record.fleet_id)

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


def _check_may_time(device: Device, registered: RegistryEntry, record: RaceRecord) -> None:
    """Refuse (403) a crossing from a device that is not this race's clock; see the module docstring."""
    race = record.race
    if record.timed_by is not None and record.timed_by != device.device_id:
        raise Forbidden(f"Race {race.race_id} is timed by device {record.timed_by}; crossings from "
                        f"{device.device_id} are not counted (record laps by hand at the timekeeper desk instead).")
    if device.device_kind == DeviceKind.CAR.value and race.car not in (device.device_id, registered.hostname):
        raise Forbidden(f"Car {device.device_id} is not the car of race {race.race_id}; a car only times its own "
                        "race.")
