"""Races, each track's live pointer, stored strip outcomes and publish intents in memory: the port RaceService
(RaceRepository) and TimingService take.

Copies chalicelib/storage/races.py (DynamoRaceStore): a race is kept as its JSON with its version, so a read never
hands out the stored object. Each write is all-or-nothing, as the adapter's transactions are, and puts the racer's
publish intent with it: `create_live` needs the race id and the track's pointer free (else Conflict naming the racer
in the way); `save` and `finalise` need the stored version (a missing race fails too) and `finalise` also the
track's pointer naming this race, which it drops; a failed condition raises StaleRace. `save_with_outcome` stores the
outcome only under a free key (False when the key is taken, StaleRace when the race moved); `delete` takes the race
unconditionally. Listings come in the adapter's key order (race id); intents are overwritten per racer row, dropped
only with the token they carry, and `pending_publishes(older_than_ms)` answers those written that long ago by
`wall_ms` (the adapter's wall clock).
"""
from __future__ import annotations

import time
from collections.abc import Callable

from chalicelib.core.errors import Conflict
from chalicelib.domain.race_writes import StaleRace
from chalicelib.domain.races import PublishIntent, RaceRecord


def _wall_ms() -> int:
    return time.time_ns() // 1_000_000


class InMemoryRaceStore:
    def __init__(self, wall_ms: Callable[[], int] = _wall_ms) -> None:
        self._races: dict[tuple[str, str], tuple[int, str]] = {}  # (event, race) -> (version, the record's JSON)
        self._live: dict[tuple[str, str], tuple[str, str]] = {}  # (event, track) -> (race id, racer username)
        self._outcomes: dict[tuple[str, str], str] = {}  # (device, key) -> the outcome's JSON
        self._intents: dict[tuple[str, str, str], tuple[int, PublishIntent]] = {}  # row -> (written at, intent)
        self._wall_ms = wall_ms

    # --- reads ---
    def get(self, event_id: str, race_id: str) -> RaceRecord | None:
        found = self._races.get((event_id, race_id))
        return RaceRecord.model_validate_json(found[1]) if found else None

    def live_race_id(self, event_id: str, track_id: str) -> str | None:
        found = self._live.get((event_id, track_id))
        return found[0] if found else None

    def live_racer(self, event_id: str, track_id: str) -> str | None:
        found = self._live.get((event_id, track_id))
        return found[1] if found else None

    def list_event(self, event_id: str, *, track_id: str | None = None, racer_sub: str | None = None,
                   ) -> list[RaceRecord]:
        records = [RaceRecord.model_validate_json(doc) for (event, _), (_, doc) in sorted(self._races.items())
                   if event == event_id]
        return [r for r in records if (track_id is None or r.race.track_id == track_id)
                and (racer_sub is None or r.race.racer.sub == racer_sub)]

    def list_racer(self, racer_sub: str) -> list[RaceRecord]:
        records = [RaceRecord.model_validate_json(doc) for _, doc in self._races.values()]
        return [r for r in records if r.race.racer.sub == racer_sub]

    def get_outcome(self, device_id: str, key: str) -> str | None:
        return self._outcomes.get((device_id, key))

    # --- writes ---
    def create_live(self, record: RaceRecord) -> None:
        race = record.race
        if (race.event_id, race.race_id) in self._races or (race.event_id, race.track_id) in self._live:
            racer = self.live_racer(race.event_id, race.track_id)
            raise Conflict(f"Track {race.track_id} already has a live race"
                           f"{f' ({racer})' if racer else ''}; submit or discard it first.", field="track_id")
        self._store(record)
        self._live[(race.event_id, race.track_id)] = (race.race_id, race.racer.username)

    def save(self, record: RaceRecord, expected_version: int) -> None:
        if not self._at_version(record, expected_version):
            raise StaleRace(record.race.race_id)
        self._store(record)

    def finalise(self, record: RaceRecord, expected_version: int) -> None:
        race = record.race
        if not self._at_version(record, expected_version) or self.live_race_id(race.event_id,
                                                                              race.track_id) != race.race_id:
            raise StaleRace(race.race_id)
        self._store(record)
        del self._live[(race.event_id, race.track_id)]

    def save_with_outcome(self, record: RaceRecord | None, expected_version: int | None, device_id: str, key: str,
                          outcome_json: str) -> bool:
        race_write = record if record is not None and expected_version is not None else None
        key_free = (device_id, key) not in self._outcomes
        if key_free and (race_write is None or self._at_version(race_write, expected_version or 0)):
            self._outcomes[(device_id, key)] = outcome_json
            if race_write is not None:
                self._store(race_write)
            return True
        if not key_free:
            return False
        raise StaleRace(record.race.race_id if record else key)

    def delete(self, record: RaceRecord) -> None:
        race = record.race
        self._races.pop((race.event_id, race.race_id), None)
        self._put_intent(PublishIntent.of(race, deleted=True))

    # --- publish intents ---
    def pending_publishes(self, older_than_ms: int = 0) -> list[PublishIntent]:
        cutoff = self._wall_ms() - older_than_ms
        return [intent for _, (at_ms, intent) in sorted(self._intents.items(), key=lambda item: "#".join(item[0]))
                if older_than_ms <= 0 or at_ms <= cutoff]

    def complete_publish(self, intent: PublishIntent) -> None:
        row = (intent.event_id, intent.track_id, intent.racer_sub)
        found = self._intents.get(row)
        if found is not None and found[1].token == intent.token:
            del self._intents[row]

    # --- plumbing ---
    def _at_version(self, record: RaceRecord, expected_version: int) -> bool:
        found = self._races.get((record.race.event_id, record.race.race_id))
        return found is not None and found[0] == expected_version

    def _store(self, record: RaceRecord) -> None:
        race = record.race
        self._races[(race.event_id, race.race_id)] = (race.version, record.model_dump_json())
        self._put_intent(PublishIntent.of(race))

    def _put_intent(self, intent: PublishIntent) -> None:
        self._intents[(intent.event_id, intent.track_id, intent.racer_sub)] = (self._wall_ms(), intent)
