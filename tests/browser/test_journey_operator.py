"""Journey 3: an operator sets up event day in a real browser: a fleet, an event with two tracks, a car activated
with a code from the screen (the car exchanges it through the JSON API, as the car agent does), and the racer's
uploaded model given to that car on the cars screen."""
from __future__ import annotations

import json
import os
import shlex
import subprocess
from datetime import date
from pathlib import Path

import pytest
import requests

from tests.browser.console_api import access_token, call, create_user, sign_in
from tests.unit.models_helpers import onnx_archive

pytestmark = pytest.mark.browser

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
DREM = Path(__file__).resolve().parents[2] / ".venv" / "bin" / "drem"


def _upload_model(url: str, token: str, filename: str) -> dict:
    ticket = call(url, "POST", "/api/models", token=token, body={"filename": filename}, expect=201)
    upload = ticket["upload"]
    posted = requests.post(upload["url"], data=upload["fields"], files={"file": (filename, onnx_archive())},
                           timeout=15)
    assert posted.status_code in (200, 204), posted.text
    done = call(url, "POST", f"/api/models/{ticket['model']['model_id']}/complete", token=token, expect=200)
    assert done["model"]["status"] == "AVAILABLE", done
    return done["model"]


def test_operator_sets_up_an_event_activates_a_car_and_gives_it_the_racers_model(live_stack, app_url, page, tmp_path):
    create_user(live_stack, "journey-op", "operator")
    create_user(live_stack, "journey-racer", "racer")
    model = _upload_model(app_url, access_token(live_stack, "journey-racer"), "journey-model.tar.gz")
    sign_in(page, app_url, "journey-op")

    # A fleet for the cars of track 1.
    page.goto(app_url + "/console/fleets")
    page.fill("#name", "Track 1 cars")
    page.get_by_role("button", name="Create fleet").click()
    page.wait_for_url(app_url + "/console/fleets?done=fleet-created")
    assert page.get_by_test_id("notice").inner_text() == "Fleet created."
    assert "Track 1 cars" in page.inner_text("[data-testid=fleets-table]")

    # An event with two tracks; a mistake first, shown next to its field.
    page.goto(app_url + "/console/events/new")
    assert page.input_value("#date") == date.today().isoformat()  # a new event starts on today's date
    page.fill("#date", "2026-06-01")
    page.fill("#country_code", "Sweden (SE)")  # the label the picker's list offers
    page.fill("#track-1-title", "Main track")
    page.select_option("#track-1-fleet_id", label="Track 1 cars")
    page.check("#track-2-use")
    page.fill("#track-2-title", "Side track")
    page.get_by_role("button", name="Create event").click()
    assert page.locator("#name-error").is_visible()  # the name is missing
    assert page.input_value("#track-2-title") == "Side track"  # nothing typed is lost
    assert page.input_value("#country_code") == "Sweden (SE)"
    page.fill("#name", "Journey Summit")
    page.get_by_role("button", name="Create event").click()
    page.wait_for_url(app_url + "/console/events?done=event-created")
    assert page.get_by_test_id("notice").inner_text() == "Event created."
    row = page.locator("tr", has_text="Journey Summit")
    assert "Main track" in row.inner_text() and "Side track" in row.inner_text()
    assert row.get_by_role("link", name="Leaderboard").get_attribute("href").startswith("/leaderboard/")
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "events.png"), full_page=True)

    # Activate a car: the screen shows a one-time code and the command to run on the car.
    page.goto(app_url + "/console/cars/activate")
    page.select_option("#device_kind", "car")
    page.fill("#hostname", "deepracer-07")
    page.select_option("#fleet_id", label="Track 1 cars")
    page.get_by_role("button", name="Create activation code").click()
    code = page.inner_text("[data-testid=activation-code]").strip()
    command = page.inner_text("[data-testid=activation-command]")
    assert command == f"drem car activate --code {code} --hostname deepracer-07 --api {app_url}"
    # The operator pastes it on the car, as printed (issue 13, item 2: without --hostname it was refused).
    config = tmp_path / "car-config"
    ran = subprocess.run([str(DREM), *shlex.split(command)[1:]], cwd=tmp_path, capture_output=True, text=True,
                         timeout=60, env={**os.environ, "DREM_CAR_CONFIG": str(config)})
    assert ran.returncode == 0, ran.stderr
    credential = json.loads((config / "credential.json").read_text())["credential"]
    call(app_url, "POST", "/api/devices/self/heartbeat", device=credential,
         body={"battery_pct": 81, "agent_version": "journey"}, expect=200)

    # The car is listed online with its battery; give it the racer's model.
    page.goto(app_url + "/console/cars")
    car_row = page.locator("tr[data-hostname='deepracer-07']")
    assert "online" in car_row.inner_text() and "81 %" in car_row.inner_text()
    models_row = page.get_by_test_id("models-deepracer-07")
    assert "none assigned" in models_row.inner_text()
    models_row.get_by_label("Model for deepracer-07").select_option(model["model_id"])
    models_row.get_by_role("button", name="Assign model").click()
    page.wait_for_load_state()
    assert "journey-racer · journey-model (assigned)" in page.get_by_test_id("models-deepracer-07").inner_text()

    # The car sees the assignment through its own API.
    mine = call(app_url, "GET", "/api/devices/self/assignment", device=credential, expect=200)
    assert [m["model_id"] for m in mine["models"]] == [model["model_id"]]
