"""A console model's check (inspection + ONNX conversion) cut short by kill -9 of the app, of storage, or of
everything: the scrutineering worker resumes it from the model's own record, and the model ends AVAILABLE and
converted, never "Checking…" forever.

The kill point is the model record saying its check started (`check_started_at`, written before the check runs), read
from the API while the racer's `/complete` request is still converting.
"""
from __future__ import annotations

import threading

import pytest
import requests

from drem_local.api_client import ApiClient
from drem_local.stack import StackConfig, free_port, start_stack
from tests import console_fixture
from tests.waiting import wait_until

pytestmark = [pytest.mark.integration, pytest.mark.durability]

PASSWORD = "Check-Admin-Pass-1!"


def _ticket_and_upload(api: ApiClient, name: str, data: bytes) -> str:
    ticket = api.post("/api/models", {"filename": f"{name}.tar.gz"})
    posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"],
                           files={"file": (f"{name}.tar.gz", data)}, timeout=120)
    assert posted.status_code in (200, 204), posted.text
    return ticket["model"]["model_id"]


def _model(api: ApiClient, model_id: str) -> dict | None:
    try:
        return api.get(f"/api/models/{model_id}")["model"]
    except Exception:  # the app or storage is down or restarting
        return None


@pytest.fixture
def stack(tmp_path, monkeypatch):
    # The worker looks every second and takes over a check that started 3 s ago (in the field: 30 s and 180 s).
    monkeypatch.setenv("DREM_CHECK_STALE_AFTER_S", "3")
    monkeypatch.setenv("DREM_RESUME_CHECKS_EVERY_S", "1")
    config = StackConfig(state_dir=tmp_path / "state", app_port=free_port(), storage_port=free_port(),
                         live_port=free_port())
    running = start_stack(config, "admin", PASSWORD, timeout=120)
    yield running
    running.stop()


@pytest.mark.parametrize("killed", ["app", "storage", "everything"])
def test_a_model_check_killed_midway_is_finished_by_the_worker(stack, killed: str) -> None:
    api = ApiClient(stack.config.app_local_url)
    api.login("admin", PASSWORD)
    model_id = _ticket_and_upload(api, f"killed-{killed}", console_fixture.require_fixture().read_bytes())

    completing = threading.Thread(target=lambda: _complete_quietly(api, model_id), daemon=True)
    completing.start()
    started = wait_until(lambda: (m := _model(api, model_id)) and m.get("check_started_at") and m, 120,
                         "the model record to say its check started")
    if killed in ("app", "everything"):
        stack.app.kill_hard()
    if killed in ("storage", "everything"):
        stack.storage.kill_hard()
    if killed == "everything":
        for process in (stack.scrutineer, stack.live):
            process.kill_hard()
    assert started["status"] == "UPLOADED"

    if killed in ("storage", "everything"):
        stack.restart_storage(120)
    if killed in ("app", "everything"):
        stack.restart_app(120)
    if killed == "everything":
        stack.restart_live(120)
        stack.restart_scrutineer()
    api = ApiClient(stack.config.app_local_url)
    api.login("admin", PASSWORD)

    done = wait_until(lambda: (m := _model(api, model_id)) and m["status"] != "UPLOADED" and m, 300,
                      "the interrupted check to be finished")
    assert done["status"] == "AVAILABLE" and done["scrutiny"] == "ready", done
    assert done["converted_md5"], done  # converted to ONNX, as an uninterrupted check does
    completing.join(60)


def _complete_quietly(api: ApiClient, model_id: str) -> None:
    try:
        api.post(f"/api/models/{model_id}/complete")
    except Exception:  # the kill cut this request off: exactly the case under test
        pass
