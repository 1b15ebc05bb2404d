"""The fleets, activation and cars screens: a code and the command to run, car actions queued as device commands,
admin-only deregistration, errors next to the field."""
from __future__ import annotations

import json
import re

import pytest

from tests.unit.operator_console_helpers import field_error, text_of
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit


def _commands(console, device_id: str) -> list[dict]:
    return json.loads(console.desk.call("GET", f"/api/devices/{device_id}/commands").body)["commands"]


def _car(console, fleet: str, hostname: str = "car-1") -> str:
    return Scenario(console.desk, fleet_id=fleet).add_car(hostname)


def test_a_fleet_made_on_screen_then_an_activation_code_with_the_command_to_run(console):
    console.sign_in("op-web", "operator")
    assert console.post("/console/fleets", {"name": "Track 1 cars"}).status_code == 303
    fleet_id = json.loads(console.desk.call("GET", "/api/fleets").body)["fleets"][0]["fleet_id"]

    page = console.post("/console/cars/activate", {"device_kind": "timer", "hostname": "timer-a",
                                                   "fleet_id": fleet_id, "ttl_minutes": "30"}).body.decode()

    code = re.search(r'data-testid="activation-code">([A-Z0-9-]+)<', page).group(1)
    assert f"drem car activate --code {code} --hostname timer-a --kind timer --api http://127.0.0.1:8000" in page
    exchange = {"code": code, "hostname": "timer-a", "device_kind": "timer"}
    activated = console.desk.client.http.post("/api/devices/activate", body=json.dumps(exchange).encode(),
                                              headers={"Content-Type": "application/json"})
    assert activated.status_code == 201
    assert "timer-a" in text_of(console.web.get("/console/cars").body.decode())


def test_bad_activation_input_is_named_next_to_the_field(console):
    console.desk.fleet()
    console.sign_in("op-web", "operator")
    reply = console.post("/console/cars/activate", {"device_kind": "car", "hostname": "bad host!", "fleet_id": "x"})
    assert reply.status_code == 400
    assert field_error(reply.body.decode(), "hostname")
    assert console.post("/console/fleets", {"name": "  "}).status_code == 400
    empty = console.post("/console/fleets", {"name": ""})
    assert empty.status_code == 400 and field_error(empty.body.decode(), "name") == "Enter the name."
    long = console.post("/console/fleets", {"name": "f" * 81})
    assert field_error(long.body.decode(), "name") == "The name is too long (at most 80 characters)."
    assert 'value="' + "f" * 81 + '"' in long.body.decode()  # what was typed is kept


def test_car_actions_become_device_commands(console):
    fleet = console.desk.fleet()
    car = _car(console, fleet)
    console.sign_in("op-web", "operator")

    assert 'value="START_CAR"' in console.web.get("/console/cars").body.decode()
    for form in ({"type": "RESTART_SERVICE"}, {"type": "START_CAR"}, {"type": "EMERGENCY_STOP"},
                 {"type": "SET_TAIL_LIGHT", "colour": "sky blue"}, {"type": "DELETE_ALL_MODELS"}):
        reply = console.post(f"/console/cars/{car}/commands", form)
        assert reply.status_code == 303, reply.body

    queued = [(c["type"], c["parameters"]) for c in _commands(console, car)]
    assert queued == [("RESTART_SERVICE", {}), ("START_CAR", {}), ("EMERGENCY_STOP", {}),
                      ("SET_TAIL_LIGHT", {"colour": "#87CEEB"}), ("DELETE_ALL_MODELS", {"with_system_logs": False})]

    bad = console.post(f"/console/cars/{car}/commands", {"type": "SET_TAIL_LIGHT", "colour": "plaid"})
    assert bad.status_code == 400 and "colour must be" in text_of(bad.body.decode())


def test_a_cars_heartbeat_faults_are_shown_on_its_row(console):
    fleet = console.desk.fleet()
    credential = console.desk.device(fleet, "deepracer-07", kind="car")
    fault = "someone else logged in to the car's console; drem logs back in for staff commands and model loads"
    beat = console.desk.client.http.post("/api/devices/self/heartbeat", body=json.dumps({"faults": [fault]}).encode(),
                                         headers={"Authorization": f"Device {credential}",
                                                  "Content-Type": "application/json", "Accept": "application/json"})
    assert beat.status_code == 200, beat.body
    console.sign_in("op-web", "operator")
    page = console.web.get("/console/cars").body.decode()
    assert "someone else logged in to the car&#39;s console" in page and 'data-testid="car-fault"' in page


def test_moving_a_car_and_only_an_admin_may_deregister_it(console):
    fleet = console.desk.fleet()
    other = console.desk.fleet("Spare cars")
    car = _car(console, fleet)
    console.sign_in("op-web", "operator")

    assert console.post(f"/console/cars/{car}/fleet", {"fleet_id": other}).status_code == 303
    assert json.loads(console.desk.call("GET", f"/api/devices/{car}").body)["fleet_id"] == other
    page = console.web.get("/console/cars").body.decode()
    assert "Deregister" not in page
    assert console.post(f"/console/cars/{car}/deregister", {}).status_code == 403

    console.web.cookies.clear()
    console.sign_in("boss", "admin")
    assert "Deregister" in console.web.get("/console/cars").body.decode()
    assert console.post(f"/console/cars/{car}/deregister", {}).status_code == 303
    assert console.desk.call("GET", f"/api/devices/{car}").status_code == 404


def test_a_model_the_car_lost_and_loads_again_says_why_on_the_cars_page(console):
    """A restarted car's agent reports the model `verified` with what happened; staff read it on the car's row."""
    from tests.unit.models_helpers import ModelsApi, bearer, device_headers, onnx_archive

    fleet = console.desk.fleet()
    credential = console.desk.device(fleet, "deepracer-07", kind="car")
    racer = ModelsApi(console.desk.client, bearer(console.desk.token("rita", "racer")))
    model = racer.upload_and_complete("fast.tar.gz", onnx_archive(0.25))
    car = ModelsApi(console.desk.client, device_headers(credential))
    device_id = json.loads(car.call("GET", "/api/devices/self/assignment").body)["device_id"]
    assigned = console.desk.call("PUT", f"/api/cars/{device_id}/models", {"model_ids": [model["model_id"]]})
    assert assigned.status_code == 200, assigned.body
    why = "car restarted 10:58:12 UTC and lost fast: loading it again"
    reported = car.call("POST", "/api/devices/self/assignment/status",
                        {"model_id": model["model_id"], "status": "verified", "md5": model["archive_md5"],
                         "reason": why})
    assert reported.status_code == 200, reported.body
    console.sign_in("op-web", "operator")
    page = text_of(console.web.get("/console/cars").body.decode())
    assert f"rita · fast (verified: {why})" in page, page


def test_two_racers_called_bjorn_are_told_apart_on_the_cars_page(console):
    """Issue 31: the cars page named racers by sign-in name. Now by display name, and bjorn_a's model on the car is
    "Björn (bjorn_a)" because another Björn's model is on offer on the same page (in the page and its poll alike)."""
    from tests.unit.models_helpers import ModelsApi, bearer, onnx_archive

    fleet = console.desk.fleet()
    console.desk.device(fleet, "deepracer-08", kind="car")
    models = {}
    for bias, (username, name) in enumerate((("bjorn_a", "Björn"), ("bjorn_b", "björn"), ("yamada", "山田"))):
        token = console.desk.token(username, "racer")
        named = console.desk.client.http.put("/api/me/profile", body=json.dumps({"display_name": name}),
                                             headers={**bearer(token), "Content-Type": "application/json"})
        assert named.status_code == 200, named.body
        models[username] = ModelsApi(console.desk.client, bearer(token)).upload_and_complete(
            f"fast-{bias}.tar.gz", onnx_archive(0.1 * bias))["model_id"]
    device_id = next(d["device_id"] for d in json.loads(console.desk.call("GET", "/api/devices").body)["devices"]
                     if d["hostname"] == "deepracer-08")
    assigned = console.desk.call("PUT", f"/api/cars/{device_id}/models",
                                 {"model_ids": [models["bjorn_a"], models["yamada"]]})
    assert assigned.status_code == 200, assigned.body

    console.sign_in("op-web", "operator")
    html = console.web.get("/console/cars").body.decode()
    live = console.web.get("/console/cars/live").body.decode()
    for shown in (html, live):
        chips = [text_of(chip) for chip in re.findall(r'<span class="pill model-chip">(.*?)</span>', shown)]
        assert chips == ["Björn (bjorn_a) · fast-0 (assigned)", "山田 · fast-2 (assigned)"], chips
    options = sorted(text_of(o) for o in re.findall(r'<option value="[^"]*">([^<]*· fast-[^<]*)</option>', html))
    assert options == ["Björn (bjorn_a) · fast-0", "björn (bjorn_b) · fast-1", "山田 · fast-2"], options
