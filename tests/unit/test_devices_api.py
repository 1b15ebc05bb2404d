"""Device status (heartbeat → online board) and the command queue (staff queue → device fetches → ack → staff
sees)."""
from __future__ import annotations

from typing import Any

import pytest

from tests.unit.device_api import Api

pytestmark = pytest.mark.unit

REPORT = {"agent_version": "1.4.0", "model": {"name": "fast-lane", "md5": "0123456789abcdef0123456789abcdef"},
          "battery_pct": 81.5, "faults": ["camera warm"], "inference_latency_ms": 12.25, "fps": 15}


def test_heartbeat_puts_the_car_on_the_online_board_with_its_report(api: Api) -> None:
    fleet_id = api.fleet()
    car = api.activate(fleet_id, "car-01")
    timer = api.activate(fleet_id, "timer-01", kind="timer")

    assert api.get("/api/devices?online=true").data["devices"] == []
    beat = api.post("/api/devices/self/heartbeat", REPORT, device=car["credential"])
    assert beat.status_code == 200 and beat.data["online"] is True

    online = api.get("/api/devices?online=true").data["devices"]
    assert [d["device_id"] for d in online] == [car["device_id"]]
    line = online[0]
    assert (line["kind"], line["hostname"], line["fleet_id"]) == ("car", "car-01", fleet_id)
    assert line["telemetry"] == {**REPORT, "fps": 15.0, "times_laps": False}  # a car with no timing line of its own
    assert line["last_seen_ms"] is not None and line["seconds_since_seen"] < 5

    offline = api.get("/api/devices?online=false").data["devices"]
    assert [(d["device_id"], d["last_seen_ms"]) for d in offline] == [(timer["device_id"], None)]


def test_a_device_unseen_for_more_than_15_seconds_is_offline(api: Api, monkeypatch: pytest.MonkeyPatch) -> None:
    from chalicelib import services

    car = api.activate(api.fleet(), "car-01")
    api.post("/api/devices/self/heartbeat", {"agent_version": "1.4.0"}, device=car["credential"])
    seen_at = services.now_ms()
    monkeypatch.setattr(services, "now_ms", lambda: seen_at + 16_000)
    line = api.get(f"/api/devices/{car['device_id']}").data
    assert line["online"] is False
    assert line["telemetry"]["agent_version"] == "1.4.0"
    assert api.get("/api/devices?online=true").data["devices"] == []


def test_heartbeats_of_two_devices_do_not_overwrite_each_other(api: Api) -> None:
    fleet_id = api.fleet()
    one, two = api.activate(fleet_id, "car-01"), api.activate(fleet_id, "car-02")
    api.post("/api/devices/self/heartbeat", {"battery_pct": 50}, device=one["credential"])
    api.post("/api/devices/self/heartbeat", {"battery_pct": 90}, device=two["credential"])
    board = {d["hostname"]: d["telemetry"]["battery_pct"] for d in api.get("/api/devices").data["devices"]}
    assert board == {"car-01": 50, "car-02": 90}


def test_bad_heartbeat_is_refused_naming_the_field(api: Api) -> None:
    car = api.activate(api.fleet(), "car-01")
    bad = api.post("/api/devices/self/heartbeat", {"battery_pct": 140}, device=car["credential"])
    assert (bad.status_code, bad.data["error"]["field"]) == (400, "battery_pct")
    bad_md5 = api.post("/api/devices/self/heartbeat", {"model": {"name": "m", "md5": "xyz"}}, device=car["credential"])
    assert bad_md5.data["error"]["field"] == "model.md5"
    assert api.get(f"/api/devices/{car['device_id']}").data["online"] is False


def test_command_queue_ack_and_staff_see_the_outcome(api: Api) -> None:
    car = api.activate(api.fleet(), "car-01")
    device_id, credential = car["device_id"], car["credential"]
    stop = api.post(f"/api/devices/{device_id}/commands", {"type": "EMERGENCY_STOP"})
    light = api.post(f"/api/devices/{device_id}/commands", {"type": "SET_TAIL_LIGHT", "colour": "Sky Blue"})
    cap = api.post(f"/api/devices/{device_id}/commands", {"type": "SET_THROTTLE_CAP", "throttle_cap_pct": 60})
    assert [r.status_code for r in (stop, light, cap)] == [201, 201, 201]
    assert light.data["parameters"] == {"colour": "#87CEEB"}

    pending = api.get("/api/devices/self/commands", device=credential).data["commands"]
    assert [c["type"] for c in pending] == ["EMERGENCY_STOP", "SET_TAIL_LIGHT", "SET_THROTTLE_CAP"]
    assert pending[2]["parameters"] == {"throttle_cap_pct": 60}

    ok = api.post(f"/api/devices/self/commands/{stop.data['command_id']}/ack", {"result": "ok"}, device=credential)
    failed = api.post(f"/api/devices/self/commands/{light.data['command_id']}/ack",
                      {"result": "failed", "message": "LED driver missing"}, device=credential)
    assert (ok.status_code, failed.status_code) == (200, 200)
    again = api.post(f"/api/devices/self/commands/{stop.data['command_id']}/ack", {"result": "ok"}, device=credential)
    assert again.status_code == 409

    assert [c["type"] for c in api.get("/api/devices/self/commands", device=credential).data["commands"]] == [
        "SET_THROTTLE_CAP"]
    seen = {c["type"]: c for c in api.get(f"/api/devices/{device_id}/commands").data["commands"]}
    assert seen["EMERGENCY_STOP"]["status"] == "ok"
    assert (seen["SET_TAIL_LIGHT"]["status"], seen["SET_TAIL_LIGHT"]["message"]) == ("failed", "LED driver missing")
    assert seen["SET_THROTTLE_CAP"]["status"] == "pending"
    assert seen["EMERGENCY_STOP"]["created_by"] == "operator-user"


def test_a_device_cannot_read_or_ack_another_devices_commands(api: Api) -> None:
    fleet_id = api.fleet()
    car_x, car_y = api.activate(fleet_id, "car-x"), api.activate(fleet_id, "car-y")
    command = api.post(f"/api/devices/{car_x['device_id']}/commands", {"type": "RESTART_SERVICE"}).data

    assert api.get("/api/devices/self/commands", device=car_y["credential"]).data["commands"] == []
    stolen = api.post(f"/api/devices/self/commands/{command['command_id']}/ack", {"result": "ok"},
                      device=car_y["credential"])
    assert stolen.status_code == 404
    assert api.get(f"/api/devices/{car_x['device_id']}/commands", device=car_y["credential"]).status_code == 403
    assert api.get(f"/api/devices/{car_x['device_id']}/commands").data["commands"][0]["status"] == "pending"


@pytest.mark.parametrize(("body", "field"), [
    ({"type": "SET_TAIL_LIGHT", "colour": "mauve"}, "colour must be #RRGGBB"),
    ({"type": "SET_TAIL_LIGHT"}, "needs colour"),
    ({"type": "SET_THROTTLE_CAP", "throttle_cap_pct": 101}, "throttle_cap_pct"),
    ({"type": "SELF_DESTRUCT"}, "type"),
    ({"type": "RESTART_SERVICE", "colour": "#FF0000"}, "colour only applies"),
])
def test_bad_commands_are_refused(api: Api, body: dict[str, Any], field: str) -> None:
    car = api.activate(api.fleet(), "car-01")
    reply = api.post(f"/api/devices/{car['device_id']}/commands", body)
    assert reply.status_code == 400
    assert field in reply.data["error"]["message"]
    assert api.get(f"/api/devices/{car['device_id']}/commands").data["commands"] == []


def test_timers_take_only_service_restarts(api: Api) -> None:
    timer = api.activate(api.fleet(), "timer-01", kind="timer")
    refused = api.post(f"/api/devices/{timer['device_id']}/commands", {"type": "EMERGENCY_STOP"})
    assert (refused.status_code, refused.data["error"]["field"]) == (400, "type")
    assert api.post(f"/api/devices/{timer['device_id']}/commands", {"type": "RESTART_SERVICE"}).status_code == 201


def test_commands_for_unknown_device_are_not_found(api: Api) -> None:
    assert api.post("/api/devices/car-ghost/commands", {"type": "RESTART_SERVICE"}).status_code == 404
    assert api.get("/api/devices/car-ghost/commands").status_code == 404
