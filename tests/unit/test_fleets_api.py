"""Fleets through the HTTP API: who may change them, the JSON, and how refusals reach the caller. The membership rules
(a car in one fleet at a time, the full member list on update, a deleted fleet's cars) are tested on the fast domain
tier, tests/domain/test_fleet_rules.py."""
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


def test_a_car_moves_fleet_through_the_api_and_an_unknown_fleet_is_named(api: Api) -> None:
    north, south = api.fleet("North"), api.fleet("South")
    car = api.activate(north, "car-01")["device_id"]
    assert api.get(f"/api/fleets/{north}").data["device_ids"] == [car]

    moved = api.put(f"/api/devices/{car}/fleet", {"fleet_id": south})
    assert moved.status_code == 200
    assert moved.data["fleet_id"] == south
    assert api.get(f"/api/fleets/{south}").data["device_ids"] == [car]

    unknown = api.put(f"/api/devices/{car}/fleet", {"fleet_id": "nope"})
    assert unknown.status_code == 400
    assert unknown.data["error"]["field"] == "fleet_id"
    assert api.get(f"/api/devices/{car}").data["fleet_id"] == south
