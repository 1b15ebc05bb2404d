"""Car/timer activation and device credentials over HTTP: the credential at work on device routes, what is stored,
request validation, roles, rotation and deregistration through the API. The rules of codes (binding to kind and host,
expiry, single use, resuming a lost answer) are tested on the fast domain tier, tests/domain/test_activation_rules.py.
"""
from __future__ import annotations

import json
from typing import Any

import pytest

from tests.unit.device_api import Api

pytestmark = pytest.mark.unit


def activate_with(api: Api, code: str, hostname: str = "car-01", kind: str = "car") -> Any:
    return api.post("/api/devices/activate", {"code": code, "hostname": hostname, "device_kind": kind}, as_=None)


def test_code_is_single_use_and_gives_a_working_credential(api: Api) -> None:
    fleet_id = api.fleet()
    code = api.activation_code(fleet_id, "car-01")
    first = activate_with(api, code)
    assert first.status_code == 201
    assert first.data["fleet_id"] == fleet_id
    credential = first.data["credential"]
    assert credential.startswith(first.data["device_id"] + ".")

    again = activate_with(api, code)
    assert again.status_code == 400
    assert again.data["error"]["field"] == "code"
    assert "already been used" in again.data["error"]["message"]

    me = api.get("/api/devices/self", device=credential)
    assert me.status_code == 200
    assert (me.data["device_id"], me.data["kind"], me.data["hostname"]) == (first.data["device_id"], "car", "car-01")
    # Exactly one device came of it.
    assert [d["hostname"] for d in api.get("/api/devices").data["devices"]] == ["car-01"]


def test_code_is_typed_loosely_but_only_the_hash_is_stored(api: Api, aws_clients: Any) -> None:
    from chalicelib.settings import get_settings

    code = api.activation_code(api.fleet(), "car-01")
    items = aws_clients.dynamodb.scan(TableName=get_settings().table("fleet"))["Items"]
    assert not any(code.replace("-", "") in str(item) or code in str(item) for item in items)
    assert activate_with(api, code.lower().replace("-", " ")).status_code == 201


def test_code_request_is_validated(api: Api) -> None:
    fleet_id = api.fleet()
    codes = "/api/devices/activation-codes"
    bad_kind = api.post(codes, {"fleet_id": fleet_id, "hostname": "c1", "device_kind": "drone"})
    assert bad_kind.data["error"]["field"] == "device_kind"
    bad_host = api.post("/api/devices/activation-codes", {"fleet_id": fleet_id, "hostname": "-x", "device_kind": "car"})
    assert bad_host.data["error"]["field"] == "hostname"
    no_fleet = api.post("/api/devices/activation-codes", {"fleet_id": "nope", "hostname": "c1", "device_kind": "car"})
    assert (no_fleet.status_code, no_fleet.data["error"]["field"]) == (400, "fleet_id")
    too_long = api.post("/api/devices/activation-codes",
                        {"fleet_id": fleet_id, "hostname": "c1", "device_kind": "car", "ttl_minutes": 100_000})
    assert too_long.data["error"]["field"] == "ttl_minutes"
    racer = api.post("/api/devices/activation-codes", {"fleet_id": fleet_id, "hostname": "c1", "device_kind": "car"},
                     as_="racer")
    assert racer.status_code == 403


def test_redeeming_is_conditional_so_a_race_for_one_code_registers_one_device(api: Api) -> None:
    """Two devices that both read the code before either redeemed it: only the first transaction goes through."""
    from chalicelib import services
    from chalicelib.domain.activation import ActivationExchange, normalise_code, sha256_hex
    from chalicelib.domain.devices import DeviceRecord, StatusEntry

    code = api.activation_code(api.fleet(), "car-01")
    store, _ = (services.device_store(), services.fleet_store())
    code_hash = sha256_hex(normalise_code(code))
    assert store.get_activation(code_hash) is not None
    exchange = ActivationExchange(code=code, hostname="car-01", device_kind="car")

    def record(device_id: str) -> DeviceRecord:
        return DeviceRecord(device_id=device_id, kind="car", hostname="car-01", secret_hash="0" * 64,
                            registered_at_ms=services.now_ms())

    def redeem(device: DeviceRecord) -> bool:
        return store.redeem(code_hash, exchange, services.now_ms(), device, StatusEntry.for_device(device), None)

    assert redeem(record("car-first")) is True
    assert redeem(record("car-second")) is False
    assert store.get_device("car-first") is not None
    assert store.get_device("car-second") is None
    # The device and its status-board line were written in the same transaction: both or neither.
    assert set(store.status_board()) == {"car-first"}


def activate_attempt(api: Api, code: str, attempt_id: str | None, hostname: str = "car-01") -> Any:
    body = {"code": code, "hostname": hostname, "device_kind": "car"}
    return api.post("/api/devices/activate", body if attempt_id is None else {**body, "attempt_id": attempt_id},
                    as_=None)


ATTEMPT = "attempt-0123456789abcdef"


def test_an_activation_whose_answer_was_lost_is_resumed_by_the_same_attempt(api: Api) -> None:
    """The app stored the activation, then the answer never reached the car (crash, WiFi): the car's retry with the
    same attempt id gets a working credential for the same device, and the lost secret stops working."""
    code = api.activation_code(api.fleet(), "car-01")
    lost = activate_attempt(api, code, ATTEMPT)
    assert lost.status_code == 201  # ... but imagine the car never read this answer

    retry = activate_attempt(api, code, ATTEMPT)
    assert retry.status_code == 201
    assert retry.data["device_id"] == lost.data["device_id"]
    assert api.get("/api/devices/self", device=retry.data["credential"]).status_code == 200
    assert api.get("/api/devices/self", device=lost.data["credential"]).status_code == 401
    assert [d["device_id"] for d in api.get("/api/devices").data["devices"]] == [lost.data["device_id"]]


def test_rotation_invalidates_the_old_secret_at_once(api: Api) -> None:
    old = api.activate(api.fleet(), "car-01")["credential"]
    rotated = api.post("/api/devices/self/rotate", device=old)
    assert rotated.status_code == 200
    new = rotated.data["credential"]
    assert new != old and new.split(".")[0] == old.split(".")[0]
    assert api.get("/api/devices/self", device=old).status_code == 401
    assert api.get("/api/devices/self", device=new).status_code == 200


def test_deregistration_is_admin_only_and_stops_the_device_at_once(api: Api) -> None:
    device = api.activate(api.fleet(), "car-01")
    device_id, credential = device["device_id"], device["credential"]
    assert api.post("/api/devices/self/heartbeat", {}, device=credential).status_code == 200

    assert api.delete(f"/api/devices/{device_id}", as_="operator").status_code == 403
    assert api.delete(f"/api/devices/{device_id}", as_="admin").status_code == 204
    assert api.post("/api/devices/self/heartbeat", {}, device=credential).status_code == 401
    assert api.get("/api/devices/self/commands", device=credential).status_code == 401
    assert api.get("/api/devices").data["devices"] == []
    assert api.get(f"/api/devices/{device_id}").status_code == 404


@pytest.mark.parametrize("credential", ["", "no-dot", "car-unknown.secret", ".secret", "car-x."])
def test_malformed_or_unknown_device_credentials_are_refused(api: Api, credential: str) -> None:
    assert api.get("/api/devices/self", device=credential).status_code == 401


def test_forged_secret_for_a_real_device_is_refused(api: Api) -> None:
    device = api.activate(api.fleet(), "car-01")
    assert api.get("/api/devices/self", device=f"{device['device_id']}.guessed-secret").status_code == 401


def test_users_cannot_call_device_routes_and_devices_cannot_call_staff_routes(api: Api) -> None:
    credential = api.activate(api.fleet(), "car-01")["credential"]
    assert api.post("/api/devices/self/heartbeat", {}, as_="admin").status_code == 403
    assert api.get("/api/devices", device=credential).status_code == 403
    assert api.post("/api/events", {}, device=credential).status_code == 403


def test_activation_needs_no_csrf_token_and_a_session_cookie_riding_along_changes_nothing(api: Api) -> None:
    code = api.activation_code(api.fleet(), "car-01")
    staff_session = api.token("admin")
    exchange = {"code": code, "hostname": "car-01", "device_kind": "car"}

    # No drem_csrf cookie, no X-CSRF-Token header: a device has neither, and no session to protect.
    plain = api.client.http.post("/api/devices/activate", body=json.dumps(exchange).encode(),
                                 headers={"Content-Type": "application/json", "Accept": "application/json"})
    assert plain.status_code == 201, plain.body
    # A forged cross-site post with someone's session cookie gets no further than an anonymous one.
    replay = api.client.http.post("/api/devices/activate", body=json.dumps(exchange).encode(), headers={
        "Content-Type": "application/json", "Accept": "application/json", "Cookie": f"drem_session={staff_session}"})
    assert replay.status_code == 400 and "already been used" in json.loads(replay.body)["error"]["message"]
