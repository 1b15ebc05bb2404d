"""The timekeeper's On-deck panel in a real browser: an operator lines racers up with their models, readies the
head's race in one click (the race panel follows on its own), and watches the next racer's model go to the free car
and load there while the race runs (the car's reports and heartbeat, sent through the JSON API as the car agent does).
Screenshots at the big screen's and a phone's size land in test-artifacts/ (copied to docs/screenshots/)."""
from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import pytest
import requests

from tests.browser.console_api import access_token, call, create_user, sign_in
from tests.unit.models_helpers import onnx_archive

pytestmark = pytest.mark.browser

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
BIG_SCREEN = {"width": 1920, "height": 1080}
PHONE = {"width": 390, "height": 844}
RACERS = ("deck-ann", "deck-ben", "deck-cy", "deck-dee", "deck-eve")


def _upload_model(url: str, token: str, filename: str, archive: bytes) -> dict:
    ticket = call(url, "POST", "/api/models", token=token, body={"filename": filename}, expect=201)
    upload = ticket["upload"]
    posted = requests.post(upload["url"], data=upload["fields"], files={"file": (filename, archive)}, timeout=15)
    assert posted.status_code in (200, 204), posted.text
    return call(url, "POST", f"/api/models/{ticket['model']['model_id']}/complete", token=token, expect=200)["model"]


def _car(url: str, token: str, fleet_id: str, hostname: str) -> str:
    code = call(url, "POST", "/api/devices/activation-codes", token=token, expect=201,
                body={"fleet_id": fleet_id, "hostname": hostname, "device_kind": "car"})["code"]
    credential = call(url, "POST", "/api/devices/activate", expect=201,
                      body={"code": code, "hostname": hostname, "device_kind": "car"})["credential"]
    call(url, "POST", "/api/devices/self/heartbeat", device=credential, body={"battery_pct": 90})
    return credential


def _add(page: Any, racer: str, model: str) -> None:
    page.fill("#queue_racer", racer)
    page.fill("#queue_model", model)
    page.get_by_role("button", name="Add to queue").click()


def _add_anyway(page: Any, racer: str, model: str) -> None:
    """Add a racer whose model has not passed scrutineering (these tiny test graphs do not lap): staff are asked
    first, and say yes."""
    _add(page, racer, model)
    warning = page.get_by_test_id("queue-scrutiny-warning")
    warning.wait_for()
    assert model in warning.inner_text()
    page.get_by_test_id("queue-add-anyway").click()


def _on_deck(page: Any) -> list[str]:
    return [name.strip() for name in page.locator("[data-testid=on-deck-row] .tk-deck-racer").all_inner_texts()]


def test_the_timekeeper_lines_racers_up_and_the_next_model_loads_on_a_free_car(live_stack, app_url, chromium, page):
    create_user(live_stack, "deck-op", "operator")
    archives: dict[str, bytes] = {}
    for index, racer in enumerate(RACERS):
        create_user(live_stack, racer, "racer")
        archives[racer] = onnx_archive(0.05 * (index + 1))
        _upload_model(app_url, access_token(live_stack, racer), f"{racer}-fast.tar.gz", archives[racer])
    token = access_token(live_stack, "deck-op")
    fleet = call(app_url, "POST", "/api/fleets", token=token, body={"name": "On-deck fleet"}, expect=201)
    cars = {hostname: _car(app_url, token, fleet["fleet_id"], hostname) for hostname in ("car-a", "car-b")}
    event = call(app_url, "POST", "/api/events", token=token, expect=201, body={
        "name": "On-deck Cup", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-07-01", "country_code": "SE",
        "race_config": {"race_time_min": 3}, "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"],
                                                         "leaderboard_title": "Main track"}]})
    timekeeper = f"{app_url}/console/timekeeper/{event['event_id']}/1"

    page.set_viewport_size(BIG_SCREEN)
    sign_in(page, app_url, "deck-op")
    page.goto(timekeeper)
    assert "Nobody in line" in page.get_by_test_id("queue-panel").inner_text()

    _add(page, "deck-ann", "deck-ben-fast")  # someone else's model: refused next to the field, nothing lost
    error = page.locator("#queue_model-error")
    error.wait_for()
    assert "deck-ann has no model ready to race named 'deck-ben-fast'" in error.inner_text()
    assert page.input_value("#queue_racer") == "deck-ann"

    for racer in RACERS:
        _add_anyway(page, racer, f"{racer}-fast")
        page.locator(f"[data-testid=queue-panel] strong:text-is('{racer}')").wait_for()
    assert _on_deck(page) == ["deck-ann", "deck-ben", "deck-cy"]
    assert "deck-dee" in page.get_by_test_id("queue-later").inner_text()
    # Each racer after the three on deck has their own place (a flex row once numbered every one "3.").
    later = page.locator("[data-testid=later-row] .tk-later-pos").all_inner_texts()
    assert later == ["4.", "5."]
    page.get_by_role("button", name="Move deck-cy up").click()
    page.wait_for_function("() => [...document.querySelectorAll('[data-testid=on-deck-row] .tk-deck-racer')]"
                           ".map(e => e.textContent).join() === 'deck-ann,deck-cy,deck-ben'")
    assert "assigned to car-a" in page.get_by_test_id("preload").inner_text()

    # The Cars page, open on another tab from here on: its model rows follow the queue's assignments live.
    cars_page = page.context.new_page()
    cars_page.goto(f"{app_url}/console/cars")
    assert cars_page.get_by_test_id("models-car-b").get_by_test_id("assigned-models").inner_text() == "none assigned"
    page.get_by_test_id("start-head").click()  # "Ready race for deck-ann on car-a"
    page.wait_for_function("() => document.querySelector('[data-testid=racer]')?.textContent === 'deck-ann'")
    assert "car-a" in page.get_by_test_id("race-panel").inner_text()
    page.keyboard.press("Space")  # start the clock
    page.wait_for_function("() => document.querySelector('[data-testid=race-status]').textContent === 'Running'")
    page.wait_for_function("() => document.querySelector('[data-testid=on-deck-row] .tk-deck-racer')"
                           "?.textContent === 'deck-cy'")
    preload = page.get_by_test_id("preload")
    assert "assigned to car-b" in preload.inner_text()

    # car-b, the free car, fetches deck-cy's model and loads it while deck-ann races on car-a.
    assignment = call(app_url, "GET", "/api/devices/self/assignment", device=cars["car-b"])
    model_id = assignment["models"][0]["model_id"]
    assert assignment["models"][0]["name"] == "deck-cy-fast"
    call(app_url, "POST", "/api/devices/self/assignment/status", device=cars["car-b"],
         body={"model_id": model_id, "status": "downloading"})
    page.wait_for_function("() => document.querySelector('[data-testid=preload]').dataset.state === 'loading'")
    call(app_url, "POST", "/api/devices/self/heartbeat", device=cars["car-b"], body={
        "battery_pct": 88, "model": {"name": "deck-cy-fast", "md5": hashlib.md5(archives["deck-cy"]).hexdigest()}})
    page.wait_for_function("() => document.querySelector('[data-testid=preload]').dataset.state === 'loaded'")
    assert "loaded on car-b" in preload.inner_text()
    # Without a reload the Cars tab shows what car-b was given and that it is the model the car has loaded.
    cars_page.wait_for_function("() => document.querySelector('[data-testid=models-car-b] "
                                "[data-testid=assigned-models]').textContent.includes('deck-cy-fast (loaded)')",
                                timeout=20_000)
    cars_page.close()

    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "timekeeper-queue-1920x1080.png"))
    phone = chromium.new_context(viewport=PHONE)
    small = phone.new_page()
    sign_in(small, app_url, "deck-op")
    small.goto(timekeeper)
    small.get_by_test_id("on-deck").wait_for()
    assert small.evaluate("() => document.documentElement.scrollWidth") <= PHONE["width"]  # no sideways scrolling
    small.screenshot(path=str(ARTIFACTS / "timekeeper-queue-390x844.png"), full_page=True)
    phone.close()

    # deck-ann's race is over; the timekeeper readies deck-dee, who is in line, through the Next race form instead
    # of the queue: deck-dee leaves the line (the queue had kept them for a second race).
    page.once("dialog", lambda dialog: dialog.accept())
    page.keyboard.press("e")
    page.get_by_role("button", name="Submit race").click()
    page.get_by_role("button", name="Ready race", exact=True).wait_for()
    page.fill("#racer_username", "deck-dee")
    page.get_by_role("button", name="Ready race", exact=True).click()
    page.wait_for_function("() => document.querySelector('[data-testid=racer]')?.textContent === 'deck-dee'")
    page.wait_for_function("() => !document.querySelector('#tk-queue-list').textContent.includes('deck-dee')")
    assert _on_deck(page) == ["deck-cy", "deck-ben", "deck-eve"]


def test_with_one_car_the_ready_button_names_the_car_a_race_ended_elsewhere_freed(live_stack, app_url, page):
    """Issue 31: one car; while it raced, the next racer waited with "No free car"; the race was ended elsewhere
    (here through the API, as race admin or a timer does) and "Ready race for X" named no car, yet used car-1."""
    create_user(live_stack, "solo-op", "operator")
    for index, racer in enumerate(("solo-ann", "solo-ben")):
        create_user(live_stack, racer, "racer")
        _upload_model(app_url, access_token(live_stack, racer), f"{racer}-fast.tar.gz", onnx_archive(0.1 * (index + 1)))
    token = access_token(live_stack, "solo-op")
    fleet = call(app_url, "POST", "/api/fleets", token=token, body={"name": "One-car fleet"}, expect=201)
    _car(app_url, token, fleet["fleet_id"], "solo-car")
    event = call(app_url, "POST", "/api/events", token=token, expect=201, body={
        "name": "One-car Cup", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-07-02", "country_code": "SE",
        "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"]}]})
    page.set_viewport_size(BIG_SCREEN)
    sign_in(page, app_url, "solo-op")
    page.goto(f"{app_url}/console/timekeeper/{event['event_id']}/1")
    _add_anyway(page, "solo-ann", "solo-ann-fast")
    page.get_by_test_id("start-head").click()
    page.wait_for_function("() => document.querySelector('[data-testid=racer]')?.textContent === 'solo-ann'")
    race_id = page.locator("[data-race-id]").first.get_attribute("data-race-id")
    _add_anyway(page, "solo-ben", "solo-ben-fast")
    page.wait_for_function("() => document.querySelector('[data-testid=preload]')?.dataset.state === 'no car'")

    for kind in ("end", "submit"):
        call(app_url, "POST", f"/api/events/{event['event_id']}/races/{race_id}/commands", token=token,
             body={"kind": kind})
    button = page.get_by_test_id("start-head")
    page.wait_for_function("() => document.querySelector('[data-testid=start-head]')?.textContent"
                           " === 'Ready race for solo-ben on solo-car'", timeout=20_000)
    assert "No free car" not in page.get_by_test_id("queue-panel").inner_text()
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "timekeeper-one-car-1920x1080.png"))
    page.set_viewport_size(PHONE)
    assert page.evaluate("() => document.documentElement.scrollWidth") <= PHONE["width"]
    page.screenshot(path=str(ARTIFACTS / "timekeeper-one-car-390x844.png"), full_page=True)
    button.click()
    page.wait_for_function("() => document.querySelector('[data-testid=racer]')?.textContent === 'solo-ben'")
    assert "solo-car" in page.get_by_test_id("race-panel").inner_text()
