"""Fleets through the HTTP API: create, rename, list with members, move cars between fleets, delete."""
from __future__ import annotations

import pytest

from tests.unit.device_api import Api

pytestmark = pytest.mark.unit


def test_fleet_crud(api: Api) -> None:
    fleet_id = api.fleet("Track 1 cars")
    assert api.get(f"/api/fleets/{fleet_id}").data["name"] == "Track 1 cars"
    renamed = api.put(f"/api/fleets/{fleet_id}", {"name": "  North track  "}, as_="admin")
    assert renamed.status_code == 200
    assert renamed.data["name"] == "North track"
    assert [f["name"] for f in api.get("/api/fleets").data["fleets"]] == ["North track"]

    assert api.delete(f"/api/fleets/{fleet_id}").status_code == 204
    assert api.get(f"/api/fleets/{fleet_id}").status_code == 404
    assert api.get("/api/fleets").data["fleets"] == []


def test_fleet_input_is_validated_and_roles_enforced(api: Api) -> None:
    blank = api.post("/api/fleets", {"name": "   "})
    assert blank.status_code == 400
    assert blank.data["error"]["field"] == "name"
    unknown_car = api.post("/api/fleets", {"name": "A", "device_ids": ["car-ghost"]})
    assert unknown_car.status_code == 400
    assert unknown_car.data["error"]["field"] == "device_ids.0"
    assert api.post("/api/fleets", {"name": "A"}, as_="racer").status_code == 403
    assert api.get("/api/fleets", as_="commentator").status_code == 403
    assert api.get("/api/fleets").data["fleets"] == []


def test_cars_move_between_fleets(api: Api) -> None:
    north = api.fleet("North")
    car_1 = api.activate(north, "car-01")["device_id"]
    car_2 = api.activate(north, "car-02")["device_id"]
    assert api.get(f"/api/fleets/{north}").data["device_ids"] == sorted([car_1, car_2])

    # Creating a fleet with a car moves it there, out of its old fleet.
    south = api.fleet("South", device_ids=[car_2])
    fleets = {f["name"]: f["device_ids"] for f in api.get("/api/fleets").data["fleets"]}
    assert fleets == {"North": [car_1], "South": [car_2]}

    # One car moved by itself.
    moved = api.put(f"/api/devices/{car_1}/fleet", {"fleet_id": south})
    assert moved.status_code == 200
    assert moved.data["fleet_id"] == south
    assert sorted(api.get(f"/api/fleets/{south}").data["device_ids"]) == sorted([car_1, car_2])

    # A fleet update sets the full member list; a car left out belongs to no fleet.
    api.put(f"/api/fleets/{south}", {"name": "South", "device_ids": [car_1]})
    assert api.get(f"/api/devices/{car_2}").data["fleet_id"] is None
    assert api.get(f"/api/fleets/{south}").data["device_ids"] == [car_1]

    # Deleting a fleet keeps its cars registered, in no fleet.
    assert api.delete(f"/api/fleets/{south}").status_code == 204
    assert api.get(f"/api/devices/{car_1}").data["fleet_id"] is None
    assert api.put(f"/api/devices/{car_1}/fleet", {"fleet_id": south}).data["error"]["field"] == "fleet_id"
