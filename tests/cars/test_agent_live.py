"""The car agent against the real local stack (durable moto + app over HTTP): activation, model pull, and a race
whose API goes away for two laps while the simulated car keeps lapping.

Every wait is for what a user would see (a status, a lap, an empty outbox); timeouts only bound a failure. The agent
runs with short poll periods (`QUICK_POLLS`) so a test waits for the agent's work, not for its idle time, and the sim
car drives five times faster than life (its world advances one frame per loop tick, so lap times stay exact)."""
from __future__ import annotations

import argparse
import hashlib
import os
import stat
import threading
import time
from pathlib import Path

import pytest
import requests

from drem_cars import cli as car_cli
from drem_cars.agent import AgentTiming, CarAgent
from drem_cars.client import DeviceClient
from drem_cars.credentials import CredentialStore
from drem_cars.model_store import ModelStore
from drem_cars.outbox import Outbox
from drem_cars.parts.safety import Safety
from drem_cars.sim_car import build_sim_car
from drem_local.api_client import ApiClient
from tests.cars.onnx_models import CONTINUOUS_SPACE, mean_brightness_policy
from tests.unit.models_helpers import UNREADABLE_IR_VERSION, onnx_archive, tar_gz
from tests.waiting import wait_until

pytestmark = pytest.mark.integration

# The agent's defaults (AgentTiming()) are for a car at an event; here it looks again five times a second.
QUICK_POLLS = AgentTiming(tick_s=0.1, command_poll_s=0.2, assignment_poll_s=0.2)
# Five times faster than life: a lap is about 1.8 s, slow enough that a loaded machine delivers each crossing before
# the next one while the API is up, fast enough that the race takes seconds, not minutes.
FIVE_TIMES_REAL_TIME_HZ = 75.0
# A restarted app answers /healthz in ~5 s on a quiet machine; on a shared one loaded to 30 it took over 30 s.
APP_START_BOUND_S = 120.0


@pytest.fixture(scope="module")
def admin(live_stack) -> ApiClient:
    api = ApiClient(live_stack.url)
    api.sign_in(live_stack.admin_username, live_stack.admin_password)
    return api


def activate_car(live_stack, admin: ApiClient, config_dir: Path, hostname: str) -> tuple[str, str]:
    """(fleet id, device id) of a car activated with `drem car activate`."""
    fleet_id = admin.post("/api/fleets", {"name": f"fleet of {hostname}"})["fleet_id"]
    code = admin.post("/api/devices/activation-codes",
                      {"fleet_id": fleet_id, "hostname": hostname, "device_kind": "car"})["code"]
    parser = argparse.ArgumentParser()
    car_cli.add_arguments(parser)
    args = parser.parse_args(["--config-dir", str(config_dir), "activate", "--code", code, "--api", live_stack.url,
                              "--hostname", hostname])
    assert car_cli.run(args) == 0
    return fleet_id, CredentialStore(config_dir).load().device_id


def upload_model(admin: ApiClient, filename: str, data: bytes) -> dict:
    ticket = admin.post("/api/models", {"filename": filename})
    posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"],
                           files={"file": (filename, data)}, timeout=30)
    assert posted.status_code in (200, 204), posted.text
    model = admin.post(f"/api/models/{ticket['model']['model_id']}/complete")["model"]
    assert model["status"] == "AVAILABLE", model
    return model


def car_runtime(config_dir: Path, safety: Safety | None = None, event_id: str | None = None):
    client = DeviceClient(CredentialStore(config_dir))
    outbox = Outbox(config_dir / "outbox.sqlite3")
    car = build_sim_car("reinvent_base", safety=safety, outbox=outbox, event_id=event_id,
                        device_id=client.device_id)
    agent = CarAgent(client, car.driver, outbox, ModelStore(config_dir / "models"), QUICK_POLLS)
    return car, agent, outbox


def statuses(admin: ApiClient, device_id: str) -> dict[str, dict | None]:
    assignment = admin.get(f"/api/cars/{device_id}/models")["assignment"]
    return {m["name"]: m["progress"] for m in assignment["models"]}


def test_activation_stores_a_private_credential_and_status_reads_the_server(live_stack, admin, tmp_path,
                                                                          capsys) -> None:
    _fleet, device_id = activate_car(live_stack, admin, tmp_path, "car-status")
    mode = stat.S_IMODE(os.stat(tmp_path / "credential.json").st_mode)
    assert mode == 0o600
    parser = argparse.ArgumentParser()
    car_cli.add_arguments(parser)
    assert car_cli.run(parser.parse_args(["--config-dir", str(tmp_path), "status"])) == 0
    printed = capsys.readouterr().out
    assert device_id in printed and '"hostname": "car-status"' in printed


def test_assigned_models_are_pulled_verified_loaded_and_reported(live_stack, admin, tmp_path) -> None:
    _fleet, device_id = activate_car(live_stack, admin, tmp_path, "car-models")
    # Too new by construction: an IR version no onnxruntime release reads, whatever version the lock installs.
    too_new = upload_model(admin, "too_new.tar.gz", onnx_archive(0.25, ir_version=UNREADABLE_IR_VERSION))
    runnable_bytes = tar_gz([("model.onnx", mean_brightness_policy([0.0, 0.0], [0.0, 0.0])),
                             ("model_metadata.json", __import__("json").dumps(
                                 {"action_space": CONTINUOUS_SPACE, "action_space_type": "continuous",
                                  "sensor": ["FRONT_FACING_CAMERA"], "neural_network": "DREM_SMALL_CNN",
                                  "training_algorithm": "behaviour_cloning", "version": "1"}).encode())])
    runnable = upload_model(admin, "runnable.tar.gz", runnable_bytes)
    car, agent, _outbox = car_runtime(tmp_path)
    agent.start()
    try:
        assigned_at = time.monotonic()
        admin.put(f"/api/cars/{device_id}/models", {"model_ids": [too_new["model_id"], runnable["model_id"]]})
        wait_until(lambda: (statuses(admin, device_id).get("runnable") or {}).get("status") == "loaded", 30,
                   "staff see the runnable model loaded")
        print(f"\nassigned → loaded (as staff see it, polls every {QUICK_POLLS.assignment_poll_s} s): "
              f"{time.monotonic() - assigned_at:.2f} s")
        seen = statuses(admin, device_id)
        assert seen["runnable"]["status"] == "loaded", seen
        assert seen["runnable"]["md5"] == hashlib.md5(runnable_bytes).hexdigest()
        assert seen["too_new"]["status"] == "failed" and "cannot load" in seen["too_new"]["reason"], seen
        assert car.driver.pilot.pilot is not None and car.driver.pilot.pilot.action_space.kind == "continuous"
        installed = ModelStore(tmp_path / "models").installed()
        assert {m.name for m in installed.values()} == {"too_new", "runnable"}, "both verified and unpacked"
        assert not any((tmp_path / "models" / ".staging").iterdir()), "no half-finished download is left"
        agent.heartbeat()
        device = admin.get(f"/api/devices/{device_id}")
        assert device["online"] and device["telemetry"]["model"]["name"] == "runnable"

        admin.post(f"/api/devices/{device_id}/commands", {"type": "SET_THROTTLE_CAP", "throttle_cap_pct": 35})
        admin.post(f"/api/devices/{device_id}/commands", {"type": "DELETE_ALL_MODELS"})

        def settled_commands() -> list[dict] | None:
            commands = admin.get(f"/api/devices/{device_id}/commands")["commands"]
            return commands if all(c["status"] != "pending" for c in commands) else None

        commands = wait_until(settled_commands, 15, "the car acknowledges both commands")
        assert {c["type"]: c["status"] for c in commands} == {"SET_THROTTLE_CAP": "ok", "DELETE_ALL_MODELS": "ok"}
        # What staff read: both models were deleted from the car. (Its assignment still names "runnable", so the car
        # pulls and loads that one again within its 2 s model check: whether it is loaded now is a matter of timing.)
        messages = {c["type"]: c["message"] for c in commands}
        assert messages["DELETE_ALL_MODELS"] == "deleted 2 model(s)", messages
        assert car.safety.throttle_cap_pct == 35
    finally:
        agent.stop()


def pushed_assignment(client: DeviceClient, admin: ApiClient, device_id: str, model_ids: list[list[str]]) -> dict:
    """Hold the car's long poll open, assign while it waits, and return its answer. A poll that had not read its
    assignment yet when staff assigned is answered "at once" (nothing was waited for): then try again with the next
    list, a few times."""
    answer: dict = {}
    for listed in model_ids:
        version = client.assignment()["version"]
        answers: list[dict] = []
        poll = threading.Thread(target=lambda v=version, into=answers: into.append(
            client.assignment(wait_for_version=v, wait_s=20)), daemon=True)
        poll.start()
        admin.put(f"/api/cars/{device_id}/models", {"model_ids": listed})
        poll.join(60)
        assert answers, "the car's long poll was answered"
        answer = answers[0]
        assert answer["change_seen_by"] in ("push", "at once"), answer
        if answer["change_seen_by"] == "push":
            return answer
    return answer


def test_an_assignment_reaches_a_waiting_car_by_push_before_any_storage_recheck_and_after_an_app_restart(
        live_stack, admin, tmp_path) -> None:
    """The app (waitress, several threads): the staff request's thread wakes the car's poll on another thread. The
    poll's storage re-read comes every 5 s (DREM_ASSIGNMENT_RECHECK_S): "push" means the write woke it first."""
    _fleet, device_id = activate_car(live_stack, admin, tmp_path, "car-push")
    model = upload_model(admin, "pushed.tar.gz", onnx_archive(0.25))
    client = DeviceClient(CredentialStore(tmp_path))
    lists = [[model["model_id"]], []] * 3
    answer = pushed_assignment(client, admin, device_id, lists)
    assert answer["change_seen_by"] == "push", answer
    running = live_stack.running
    running.app.stop()
    running.restart_app(timeout=APP_START_BOUND_S)  # a new process: its wake-ups start empty, storage is the truth
    answer = pushed_assignment(client, admin, device_id, lists)
    assert answer["change_seen_by"] == "push", answer


def laps_of(admin: ApiClient, event_id: str, race_id: str) -> list[dict]:
    view = admin.get(f"/api/events/{event_id}/races/{race_id}")
    race = view.get("race", view)
    return race["laps"]


def test_laps_survive_an_api_outage_exactly_once_and_in_order(live_stack, admin, tmp_path) -> None:
    fleet_id, device_id = activate_car(live_stack, admin, tmp_path, "car-race")
    event = admin.post("/api/events", {"name": "Outage Cup", "event_type": "AWS_SUMMIT", "date": "2026-05-14",
                                       "country_code": "SE", "race_config": {"race_time_min": 10},
                                       "tracks": [{"track_id": "1", "fleet_id": fleet_id}]})
    event_id = event["event_id"]
    race_id = admin.post(f"/api/events/{event_id}/races", {"track_id": "1", "car": device_id,  # a car times its race
                                                           "racer_username": live_stack.admin_username})["race_id"]
    car, agent, outbox = car_runtime(tmp_path, Safety(heartbeat_limit_s=60), event_id)
    agent.start()
    driving = threading.Thread(target=car.vehicle.start, kwargs={"rate_hz": FIVE_TIMES_REAL_TIME_HZ}, daemon=True)
    driving.start()
    running = live_stack.running
    try:
        wait_until(lambda: outbox.count("delivered") >= 2, 60,
                   "the car laps and its crossings are delivered before the outage")
        running.app.stop()  # the API is really gone: its process has exited
        outage_started_with = car.strips.queued
        # The outage lasts until two more crossings (laps of a sim car) had nowhere to go but the outbox.
        outage_started = time.monotonic()
        wait_until(lambda: car.strips.queued >= outage_started_with + 2 and outbox.count() >= 2, 90,
                   "laps kept coming while the API was down, and waited in the outbox")
        print(f"\nAPI down for {time.monotonic() - outage_started:.1f} s")
        running.restart_app(timeout=APP_START_BOUND_S)  # also records its pid in stack.json, where `drem` finds it
        restarted_with = car.strips.queued
        wait_until(lambda: car.strips.queued > restarted_with, 60, "the car crosses the line after the restart too")
        car.vehicle.stop()  # a fixed number of crossings to deliver: the backlog, and the one after the restart
        driving.join(10)
        wait_until(lambda: outbox.count() == 0, 120, "the backlog and the next crossing are delivered")
        assert outbox.count("rejected") == 0, outbox.rejected()
    finally:
        car.vehicle.stop()
        agent.stop()
        if not running.app.alive():
            running.restart_app(timeout=APP_START_BOUND_S)  # the session's other tests use this stack
    crossings = [item["timestamp_ms"] for item in _delivered_bodies(outbox)]
    assert len(crossings) == car.strips.queued, "every crossing the car made reached the server"
    laps = laps_of(admin, event_id, race_id)
    expected = [b - a for a, b in zip(crossings, crossings[1:], strict=False)]
    print(f"\n{len(crossings)} crossings, {len(laps)} laps: {[lap['time_ms'] for lap in laps]}")
    assert [lap["time_ms"] for lap in laps] == expected, "every lap once, in order (first crossing starts the race)"
    assert [lap["lap_id"] for lap in laps] == list(range(len(expected)))


def _delivered_bodies(outbox: Outbox) -> list[dict]:
    import json
    import sqlite3

    with sqlite3.connect(outbox.path) as db:
        rows = db.execute("SELECT body FROM outbox WHERE kind = 'strip_event' AND state = 'delivered' "
                          "ORDER BY seq").fetchall()
    return [json.loads(body) for (body,) in rows]


def test_drem_car_run_sim_drives_then_stops_cleanly_when_the_device_is_revoked(live_stack, admin, tmp_path,
                                                                               capsys, monkeypatch) -> None:
    _fleet, device_id = activate_car(live_stack, admin, tmp_path, "car-revoked")
    monkeypatch.setenv("DREM_CAR_NO_REEXEC", "1")
    parser = argparse.ArgumentParser()
    car_cli.add_arguments(parser)
    args = parser.parse_args(["--config-dir", str(tmp_path), "run", "--sim", "--track", "reinvent_base",
                              "--seconds", "60"])
    result: dict[str, int] = {}
    runner = threading.Thread(target=lambda: result.update(code=car_cli.run(args)), daemon=True)
    started = time.monotonic()
    runner.start()
    wait_until(lambda: admin.get(f"/api/devices/{device_id}")["online"], 20,
               "the running agent's heartbeats reach the server")
    admin.delete(f"/api/devices/{device_id}")
    runner.join(30)
    assert result.get("code") == car_cli.EXIT_REVOKED
    assert time.monotonic() - started < 40, "it stopped on the revocation, not at --seconds"
    err = capsys.readouterr().err
    assert "no longer accepts this device" in err and "drem car activate" in err
