"""The in-memory stores of the fast domain tier (tests/in_memory) behave as the DynamoDB adapters do (over moto), on
every point the domain relies on: each assertion here runs against both, so the two cannot drift apart."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import date
from typing import Any

import pytest

from chalicelib.core.errors import Conflict, NotFound
from chalicelib.domain.activation import ActivationExchange, ActivationRecord
from chalicelib.domain.devices import DeviceKind, DeviceRecord, StatusEntry, Telemetry
from chalicelib.domain.events import Event, Track
from chalicelib.domain.fleets import FleetRecord
from drem_leaderboard.models import RaceConfig
from tests.in_memory.devices import InMemoryDeviceStore
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


# --- devices: registry, activation codes, status board (tests/in_memory/devices.py vs storage/devices.py) ---

@pytest.fixture(params=["in_memory", "dynamodb"])
def devices(request: pytest.FixtureRequest) -> Any:
    if request.param == "in_memory":
        return InMemoryDeviceStore()
    from chalicelib import services

    request.getfixturevalue("stack")
    return services.device_store()


def a_code(code_hash: str = "c1", *, expires_at_ms: int = 10_000, hostname: str = "Car-01",
           kind: DeviceKind = DeviceKind.CAR) -> ActivationRecord:
    return ActivationRecord(code_hash=code_hash, fleet_id="f1", hostname=hostname, device_kind=kind,
                            expires_at_ms=expires_at_ms, created_at_ms=1, created_by="op")


def redeem(devices: Any, code_hash: str = "c1", *, device_id: str = "d1", hostname: str = "car-01",
           kind: DeviceKind = DeviceKind.CAR, now_ms: int = 5_000, attempt_hash: str | None = None) -> bool:
    exchange = ActivationExchange(code="ABCD-EFGH", hostname=hostname, device_kind=kind)
    device = DeviceRecord(device_id=device_id, kind=kind, hostname=hostname, fleet_id="f1", secret_hash="s",
                          registered_at_ms=now_ms, activated_by="op")
    return devices.redeem(code_hash, exchange, now_ms, device, StatusEntry.for_device(device), attempt_hash)


def test_a_code_registers_one_device_once_and_only_before_it_expires(devices: Any) -> None:
    devices.put_activation(a_code())
    devices.put_activation(a_code("late", expires_at_ms=5_000))
    assert not redeem(devices, "late", device_id="d0")  # expires at the moment it is used
    assert not redeem(devices, "missing", device_id="d0")
    assert not redeem(devices, kind=DeviceKind.TIMER, device_id="d0")  # the code is for a car
    assert not redeem(devices, hostname="car-02", device_id="d0")
    assert devices.get_device("d0") is None and devices.status_board() == {}
    assert devices.get_activation("c1").redeemed_device_id is None

    assert redeem(devices, hostname="CAR-01", attempt_hash="a1")  # the hostname matches whatever its case
    assert devices.get_device("d1").fleet_id == "f1"
    assert list(devices.status_board()) == ["d1"]
    code = devices.get_activation("c1")
    assert (code.redeemed_device_id, code.redeemed_attempt_hash) == ("d1", "a1")
    assert not redeem(devices, device_id="d2")  # already redeemed
    assert devices.get_device("d2") is None

    devices.put_activation(a_code("c2"))
    assert not redeem(devices, "c2", device_id="d1")  # the device id is taken: nothing is marked
    assert devices.get_activation("c2").redeemed_device_id is None
    devices.put_activation(a_code())  # a new code under the same hash starts afresh
    assert devices.get_activation("c1").redeemed_device_id is None


def test_a_device_moves_fleet_with_its_status_line(devices: Any) -> None:
    devices.put_activation(a_code())
    assert redeem(devices)
    devices.set_fleet("d1", "f2")
    assert devices.get_device("d1").fleet_id == "f2"
    assert devices.status_board()["d1"].fleet_id == "f2"
    devices.set_fleet("d1", None)
    assert devices.get_device("d1").fleet_id is None
    assert devices.status_board()["d1"].fleet_id is None

    devices.set_fleet("gone", "f2")  # a device deregistered meanwhile: nothing to move, nothing made
    assert devices.get_device("gone") is None and list(devices.status_board()) == ["d1"]


def test_deleting_a_device_takes_its_status_line_and_only_its_own(devices: Any) -> None:
    devices.put_activation(a_code())
    devices.put_activation(a_code("c2", hostname="car-02"))
    assert redeem(devices) and redeem(devices, "c2", device_id="d2", hostname="car-02")
    devices.delete_device("d1")
    devices.delete_device("d1")  # deleting what is gone is not an error
    assert devices.get_device("d1") is None
    assert list(devices.status_board()) == ["d2"]
    assert devices.get_device("d2").hostname == "car-02"


def test_a_heartbeat_stamps_only_an_existing_line(devices: Any) -> None:
    assert not devices.record_heartbeat("d1", 7_000, Telemetry(battery_pct=50))
    assert devices.status_board() == {}
    devices.put_activation(a_code())
    assert redeem(devices)
    assert devices.record_heartbeat("d1", 7_000, Telemetry(battery_pct=50.5, faults=["camera"]))
    line = devices.status_board()["d1"]
    assert (line.last_seen_ms, line.telemetry) == (7_000, Telemetry(battery_pct=50.5, faults=["camera"]))
    assert devices.replace_secret_hash("d1", "s2") and devices.get_device("d1").secret_hash == "s2"
    assert not devices.replace_secret_hash("gone", "s2")
