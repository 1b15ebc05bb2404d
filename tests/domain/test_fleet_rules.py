"""The rules of fleets, on the fast domain tier: FleetService over the in-memory stores (tests/in_memory), no moto
and no HTTP. Roles, the 400/404 answers and the JSON stay in tests/unit/test_fleets_api.py."""
from __future__ import annotations

from dataclasses import dataclass

import pytest

from chalicelib.core.errors import InvalidInput, NotFound
from chalicelib.core.principals import User
from chalicelib.domain.activation import ActivationExchange, ActivationRecord
from chalicelib.domain.devices import DeviceKind, DeviceRecord, StatusEntry
from chalicelib.domain.fleets import FleetInput, FleetService
from tests.in_memory.devices import InMemoryDeviceStore
from tests.in_memory.events import InMemoryFleetStore

pytestmark = pytest.mark.domain

ADMIN = User(sub="admin-sub", username="admin", groups=frozenset({"admin"}))


@dataclass
class Garage:
    service: FleetService
    devices: InMemoryDeviceStore

    def fleet(self, name: str, device_ids: list[str] | None = None) -> str:
        return self.service.create_fleet(ADMIN, FleetInput(name=name, device_ids=device_ids)).fleet_id

    def car(self, hostname: str, fleet_id: str) -> str:
        """A car activated into `fleet_id` (the way ActivationService registers one: redeeming a code)."""
        code = ActivationRecord(code_hash=f"code-{hostname}", fleet_id=fleet_id, hostname=hostname,
                                device_kind=DeviceKind.CAR, expires_at_ms=10**13, created_at_ms=1, created_by="op")
        self.devices.put_activation(code)
        device = DeviceRecord(device_id=f"id-{hostname}", kind=DeviceKind.CAR, hostname=hostname, fleet_id=fleet_id,
                              secret_hash="s", registered_at_ms=2, activated_by="op")
        exchange = ActivationExchange(code="ABCD-EFGH", hostname=hostname, device_kind=DeviceKind.CAR)
        assert self.devices.redeem(code.code_hash, exchange, 3, device, StatusEntry.for_device(device), None)
        return device.device_id

    def members(self) -> dict[str, list[str]]:
        return {f.name: f.device_ids for f in self.service.list_fleets()}


@pytest.fixture
def garage() -> Garage:
    devices = InMemoryDeviceStore()
    return Garage(FleetService(InMemoryFleetStore(), devices, lambda: 1_000), devices)


def test_fleets_are_listed_by_name_whatever_the_case(garage: Garage) -> None:
    for name in ("north", "Middle", "South"):
        garage.fleet(name)
    assert list(garage.members()) == ["Middle", "north", "South"]


def test_cars_move_between_fleets_and_a_car_belongs_to_one_fleet_at_a_time(garage: Garage) -> None:
    north = garage.fleet("North")
    car_1, car_2 = garage.car("car-01", north), garage.car("car-02", north)
    assert garage.service.get_fleet(north).device_ids == sorted([car_1, car_2])

    south = garage.fleet("South", device_ids=[car_2])  # creating a fleet with a car moves it there
    assert garage.members() == {"North": [car_1], "South": [car_2]}

    garage.service.update_fleet(ADMIN, south, FleetInput(name="South", device_ids=[car_1]))  # the full member list
    assert garage.members() == {"North": [], "South": [car_1]}
    assert garage.devices.get_device(car_2).fleet_id is None  # left out: in no fleet, still registered

    garage.service.update_fleet(ADMIN, south, FleetInput(name="South side"))  # no list: members unchanged
    assert garage.members() == {"North": [], "South side": [car_1]}


def test_a_deleted_fleet_leaves_its_cars_registered_in_no_fleet(garage: Garage) -> None:
    north = garage.fleet("North")
    car = garage.car("car-01", north)
    garage.service.delete_fleet(ADMIN, north)
    with pytest.raises(NotFound):
        garage.service.get_fleet(north)
    assert garage.devices.get_device(car).fleet_id is None
    assert garage.devices.status_board()[car].fleet_id is None


def test_an_unknown_car_is_refused_naming_it_and_nothing_is_made_or_moved(garage: Garage) -> None:
    north = garage.fleet("North")
    car = garage.car("car-01", north)
    with pytest.raises(InvalidInput) as refused:
        garage.fleet("South", device_ids=[car, "car-ghost"])
    assert refused.value.field == "device_ids.1"
    assert garage.members() == {"North": [car]}
    with pytest.raises(InvalidInput):  # the rename in the same refused edit does not happen either
        garage.service.update_fleet(ADMIN, north, FleetInput(name="Renamed", device_ids=["car-ghost"]))
    assert garage.members() == {"North": [car]}
