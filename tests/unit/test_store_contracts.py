"""The in-memory stores of the fast domain tier (tests/in_memory) behave as the DynamoDB adapters do (over moto), on
every point the domain relies on: each assertion here runs against both, so the two cannot drift apart."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import date
from typing import Any

import pytest

from chalicelib.core.errors import Conflict, NotFound
from chalicelib.domain.events import Event, Track
from chalicelib.domain.fleets import FleetRecord
from drem_leaderboard.models import RaceConfig
from tests.in_memory.events import InMemoryEventStore, InMemoryFleetStore, InMemoryLiveRaceProbe

pytestmark = pytest.mark.unit


@dataclass
class EventPorts:
    events: Any
    fleets: Any
    live: Any
    start_race: Callable[[str, str], None]  # a race goes live on (event, track), as the race service marks it
    end_race: Callable[[str, str], None]


@pytest.fixture(params=["in_memory", "dynamodb"])
def ports(request: pytest.FixtureRequest) -> EventPorts:
    if request.param == "in_memory":
        probe = InMemoryLiveRaceProbe()
        return EventPorts(InMemoryEventStore(), InMemoryFleetStore(), probe, probe.start, probe.end)

    from chalicelib import services
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.events import DynamoLiveRaceProbe

    request.getfixturevalue("stack")
    races_table = get_settings().table("races")

    def live_key(event_id: str, track_id: str) -> dict[str, Any]:
        return {"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": f"LIVE#{track_id}"}}

    def start(event_id: str, track_id: str) -> None:
        clients.dynamodb().put_item(TableName=races_table, Item={**live_key(event_id, track_id), "raceId": {"S": "r"}})

    def end(event_id: str, track_id: str) -> None:
        clients.dynamodb().delete_item(TableName=races_table, Key=live_key(event_id, track_id))

    return EventPorts(services.event_store(), services.fleet_store(),
                      DynamoLiveRaceProbe(clients.dynamodb(), races_table), start, end)


def an_event(event_id: str = "e1", version: int = 1, name: str = "Summit") -> Event:
    return Event(event_id=event_id, name=name, event_type="AWS_SUMMIT", date=date(2026, 5, 14), country_code="SE",
                 sponsor="", race_config=RaceConfig(), tracks=(Track(track_id="1"),), landing_page_links=(),
                 created_at_ms=1, created_by="op", updated_at_ms=1, version=version)


def test_an_event_reads_back_as_written_and_a_missing_one_is_none(ports: EventPorts) -> None:
    assert ports.events.get("e1") is None
    ports.events.create(an_event())
    assert ports.events.get("e1") == an_event()
    assert ports.events.list() == [an_event()]


def test_creating_an_event_id_twice_is_a_conflict_and_keeps_the_first(ports: EventPorts) -> None:
    ports.events.create(an_event(name="First"))
    with pytest.raises(Conflict, match="already exists"):
        ports.events.create(an_event(name="Second"))
    assert ports.events.get("e1").name == "First"


def test_replace_is_conditional_on_the_stored_version(ports: EventPorts) -> None:
    ports.events.create(an_event())
    ports.events.replace(an_event(version=2, name="Renamed"), expected_version=1)
    assert ports.events.get("e1").name == "Renamed"

    with pytest.raises(Conflict, match="changed this event meanwhile"):  # a second editor, still on version 1
        ports.events.replace(an_event(version=2, name="Stale"), expected_version=1)
    assert ports.events.get("e1").name == "Renamed"
    with pytest.raises(Conflict):  # nothing to replace fails the condition too
        ports.events.replace(an_event(event_id="nope", version=2), expected_version=1)
    assert ports.events.get("nope") is None


def test_deleting_an_event_twice_is_not_found(ports: EventPorts) -> None:
    ports.events.create(an_event())
    ports.events.create(an_event(event_id="e2"))
    ports.events.delete("e1")
    assert ports.events.get("e1") is None
    assert [e.event_id for e in ports.events.list()] == ["e2"]
    with pytest.raises(NotFound, match="no event e1"):
        ports.events.delete("e1")


def test_the_live_marker_answers_per_event_and_track(ports: EventPorts) -> None:
    ports.start_race("e1", "2")
    assert ports.live.has_live_race("e1", "2")
    assert not ports.live.has_live_race("e1", "1")
    assert not ports.live.has_live_race("e2", "2")
    ports.end_race("e1", "2")
    assert not ports.live.has_live_race("e1", "2")


def test_fleets_are_put_over_listed_and_deleted_without_fuss(ports: EventPorts) -> None:
    first = FleetRecord(fleet_id="f1", name="North", created_at_ms=1, created_by="op")
    assert ports.fleets.get_fleet("f1") is None and not ports.fleets.fleet_exists("f1")
    ports.fleets.put_fleet(first)
    ports.fleets.put_fleet(first.model_copy(update={"name": "North cars"}))  # a put overwrites
    assert ports.fleets.get_fleet("f1").name == "North cars"
    assert ports.fleets.fleet_exists("f1")
    assert [f.fleet_id for f in ports.fleets.list_fleets()] == ["f1"]
    ports.fleets.delete_fleet("f1")
    ports.fleets.delete_fleet("f1")  # deleting what is gone is not an error
    assert ports.fleets.list_fleets() == []
