"""Background scrutineering in a real browser: a racer uploads a model on My models and, without reloading, watches it
go from queued to its verdict with its figures and a top-down clip; an operator who sends a model that has not
passed to a car is asked first and may send it anyway. Screenshots at 1920x1080 and 390x844 land in test-artifacts/
(copied to docs/screenshots/)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.browser.console_api import access_token, call, create_user, sign_in, upload_model
from tests.unit.models_helpers import onnx_archive

pytestmark = pytest.mark.browser

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"
SCREENSHOTS = ROOT / "test-artifacts"  # the reviewed copies live in docs/screenshots/



def test_my_models_shows_the_background_drive_without_a_reload(live_stack, app_url, page) -> None:
    create_user(live_stack, "scr-page", "racer")
    sign_in(page, app_url, "scr-page")
    page.set_viewport_size({"width": 1920, "height": 1080})
    page.goto(app_url + "/console/my-models")
    page.evaluate("() => { window.__loads = 0; addEventListener('load', () => window.__loads++); }")
    page.set_input_files("#model-files", files=[{"name": "clean-laps.tar.gz", "mimeType": "application/gzip",
                                                  "buffer": SAMPLE.read_bytes()}])

    row = page.locator('[data-testid="model-row"][data-model-name="clean-laps"]')
    row.locator('[data-testid="model-status"]', has_text="Ready to race").wait_for(timeout=60_000)
    # The upload line says it in the table's words (it said "uploaded: AVAILABLE").
    page.get_by_test_id("upload-list").get_by_text("uploaded: Ready to race").wait_for()
    # queued -> driving -> its verdict, each swapped in by the box's own polling (on re:Invent 2018 unless other
    # tests of the session created coming events with other track types: the verdict may then be "failed")
    box = row.locator('[data-testid="model-scrutiny"][data-scrutineer-status="passed"], '
                      '[data-testid="model-scrutiny"][data-scrutineer-status="failed"]')
    box.wait_for(timeout=240_000)
    result = box.get_by_test_id("scrutineer-result").inner_text()
    # The track by its name, never the enum value (issue 13, item 18).
    assert re.search(r"^(passed|failed) on (re:Invent \d{4}( · [^:]+)?|[A-Z][^:_]*): [0-2]/2 laps completed, "
                     r"best lap .+, \d+ off-tracks?$", result), result
    assert page.url == app_url + "/console/my-models" and page.evaluate("window.__loads") == 0  # never reloaded

    box.get_by_text("Watch the test drive").click()
    clip = box.locator("img")
    clip.wait_for()
    page.wait_for_function("img => img.complete && img.naturalWidth >= 200", arg=clip.element_handle())
    box.scroll_into_view_if_needed()
    SCREENSHOTS.mkdir(exist_ok=True)
    page.screenshot(path=str(SCREENSHOTS / "model-scrutiny-1920x1080.png"))
    page.set_viewport_size({"width": 390, "height": 844})
    box.scroll_into_view_if_needed()
    # On a phone each model is a card: the scrutineering result is on screen, not behind a sideways scroll.
    assert page.evaluate("() => document.documentElement.scrollWidth") <= 390
    cell = row.get_by_test_id("my-model-scrutiny").bounding_box()
    assert cell is not None and cell["x"] >= 0 and cell["x"] + cell["width"] <= 390, cell
    page.screenshot(path=str(SCREENSHOTS / "model-scrutiny-390x844.png"))


def test_sending_a_model_that_has_not_passed_to_a_car_asks_first(live_stack, app_url, page) -> None:
    create_user(live_stack, "scr-op", "operator")
    create_user(live_stack, "scr-kim", "racer")
    op = access_token(live_stack, "scr-op")
    model = upload_model(app_url, access_token(live_stack, "scr-kim"), "wobbly.tar.gz", onnx_archive(0.3))
    fleet = call(app_url, "POST", "/api/fleets", token=op, body={"name": "Scrutiny fleet"}, expect=201)
    code = call(app_url, "POST", "/api/devices/activation-codes", token=op, expect=201,
                body={"fleet_id": fleet["fleet_id"], "hostname": "car-scr", "device_kind": "car"})["code"]
    call(app_url, "POST", "/api/devices/activate", expect=201,
         body={"code": code, "hostname": "car-scr", "device_kind": "car"})

    sign_in(page, app_url, "scr-op")
    page.set_viewport_size({"width": 1920, "height": 1080})
    page.goto(app_url + "/console/models")
    page.select_option("#device_id", label="car-scr (offline)")
    page.get_by_test_id("car-status").get_by_text("This car has no models.").wait_for()  # its status is in
    page.locator(f'input[name="model_ids"][value="{model["model_id"]}"]').check()
    page.get_by_role("button", name="Send to the car", exact=True).click()

    warning = page.get_by_test_id("scrutiny-warning")
    warning.wait_for()
    assert "scr-kim – wobbly:" in warning.inner_text()  # failed, or not scrutineered yet: either way, asked
    assert page.get_by_test_id("car-model-row").count() == 0, "nothing was sent before the answer"
    warning.scroll_into_view_if_needed()
    page.screenshot(path=str(SCREENSHOTS / "send-to-car-warning-1920x1080.png"))
    page.get_by_test_id("send-anyway").click()
    page.get_by_text("Models sent to the car.").wait_for()
    assert page.locator('[data-testid="car-model-row"][data-model-name="wobbly"]').count() == 1
