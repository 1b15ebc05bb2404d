"""Events, fleets and the live-race marker in memory: the ports EventService and FleetService take.

Copies chalicelib/storage/events.py (DynamoEventStore, DynamoLiveRaceProbe) and chalicelib/storage/fleets.py
(DynamoFleetStore): an event is kept as its JSON (`doc`) with its version, so a read never hands out the stored object
and a caller's later change cannot reach the store; `create` is conditional on the id being free and `replace` on the
stored version (a missing item fails the condition too, as DynamoDB's `version = :expected` does); `delete` of a
missing event is NotFound; fleets are put and deleted unconditionally (put overwrites, deleting nothing is fine).
"""
from __future__ import annotations

from chalicelib.core.errors import Conflict, NotFound
from chalicelib.domain.events import Event
from chalicelib.domain.fleets import FleetRecord


class InMemoryEventStore:
    def __init__(self) -> None:
        self._docs: dict[str, tuple[int, str]] = {}  # event id -> (version, the event's JSON)

    def get(self, event_id: str) -> Event | None:
        found = self._docs.get(event_id)
        return Event.model_validate_json(found[1]) if found else None

    def list(self) -> list[Event]:
        return [Event.model_validate_json(doc) for _, doc in self._docs.values()]

    def create(self, event: Event) -> None:
        if event.event_id in self._docs:
            raise Conflict("An event with this id already exists.")
        self._docs[event.event_id] = (event.version, event.model_dump_json())

    def replace(self, event: Event, expected_version: int) -> None:
        found = self._docs.get(event.event_id)
        if found is None or found[0] != expected_version:
            raise Conflict("Someone else changed this event meanwhile; reload it and try again.")
        self._docs[event.event_id] = (event.version, event.model_dump_json())

    def delete(self, event_id: str) -> None:
        if self._docs.pop(event_id, None) is None:
            raise NotFound(f"There is no event {event_id}.")


class InMemoryLiveRaceProbe:
    """The race service's `LIVE#{trackId}` marker: `start`/`end` stand for a race going live and finishing."""

    def __init__(self) -> None:
        self._live: set[tuple[str, str]] = set()

    def start(self, event_id: str, track_id: str) -> None:
        self._live.add((event_id, track_id))

    def end(self, event_id: str, track_id: str) -> None:
        self._live.discard((event_id, track_id))

    def has_live_race(self, event_id: str, track_id: str) -> bool:
        return (event_id, track_id) in self._live


class InMemoryFleetStore:
    def __init__(self) -> None:
        self._fleets: dict[str, str] = {}  # fleet id -> the record's JSON

    def get_fleet(self, fleet_id: str) -> FleetRecord | None:
        found = self._fleets.get(fleet_id)
        return FleetRecord.model_validate_json(found) if found else None

    def fleet_exists(self, fleet_id: str) -> bool:
        return fleet_id in self._fleets

    def list_fleets(self) -> list[FleetRecord]:
        return [FleetRecord.model_validate_json(doc) for doc in self._fleets.values()]

    def put_fleet(self, fleet: FleetRecord) -> None:
        self._fleets[fleet.fleet_id] = fleet.model_dump_json()

    def delete_fleet(self, fleet_id: str) -> None:
        self._fleets.pop(fleet_id, None)
