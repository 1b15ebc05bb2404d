"""The learning booth's first milestone in a real browser: a racer drives the oval with the keyboard → presses Train →
the booth trainer (the worker `drem up` starts) makes v0001, which is validated, scrutineered and drives an autonomous
run → its metrics are computed → the model registry shows v0001 with them → an operator sends the racer's active
version to a car from the booth. Small on purpose (one short drive, two
epochs), so it fits in CI."""
from __future__ import annotations

import secrets
from pathlib import Path

import pytest

from drem_local import stack as local_stack
from tests.browser.console_api import access_token, call, create_user, sign_in

pytestmark = pytest.mark.browser

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
SCREENSHOTS = Path(__file__).resolve().parents[2] / "docs" / "screenshots"


@pytest.fixture(scope="module")
def booth_trainer(live_stack):
    """The trainer exactly as `drem up` starts it (drem_local.stack.start_trainer), on the session's stack."""
    trainer = local_stack.start_trainer(live_stack.running.config, live_stack.env)
    yield trainer
    trainer.stop()


def frames_reach(page, count: int) -> None:
    page.wait_for_function(
        "n => Number(document.querySelector('[data-testid=drive-frames]').textContent) >= n", arg=count)


def test_drive_train_race_and_see_v0001_with_its_metrics(app_url, live_stack, page, booth_trainer):
    username = create_user(live_stack, f"booth.{secrets.token_hex(3)}", "racer")
    sign_in(page, app_url, username)
    page.get_by_test_id("nav-links").get_by_role("link", name="Learning booth").click()
    page.wait_for_url(app_url + "/booth")
    assert page.get_by_test_id("train").is_disabled()  # nothing driven yet

    # Drive: throttle, then a little left, the way a visitor's fingers would (keyboard events, not API calls).
    page.get_by_test_id("drive-drem_oval").click()
    page.get_by_test_id("drive-start").click()
    page.get_by_test_id("drive-status").filter(has_text="Recording").wait_for()
    assert page.get_by_test_id("drive-frame").evaluate("img => img.src.startsWith('data:image/png')")
    page.keyboard.down("ArrowUp")
    frames_reach(page, 45)
    page.keyboard.down("a")
    frames_reach(page, 60)
    page.keyboard.up("a")
    frames_reach(page, 75)
    page.keyboard.up("ArrowUp")
    page.get_by_test_id("drive-finish").click()
    page.wait_for_url(f"{app_url}/booth/runs/*")
    assert page.get_by_test_id("run-status").inner_text() == "FINALISED"
    assert page.get_by_test_id("run-topdown").evaluate("img => img.complete && img.naturalWidth > 100")
    frames = int(page.get_by_test_id("run-metrics").inner_text().split("Frames")[1].split()[0])
    assert frames >= 75

    # Train: the job's live fragment goes from the queue to done, by itself (htmx polling).
    page.goto(app_url + "/booth")
    page.fill("input[name=epochs]", "2")
    page.get_by_test_id("train").click()
    job = page.get_by_test_id("job")
    job.get_by_test_id("job-state").wait_for()
    assert job.get_attribute("data-status") in ("QUEUED", "RUNNING", "DONE")
    page.locator('[data-testid=job][data-status=DONE]').wait_for(timeout=120_000)
    assert job.get_by_test_id("job-state").inner_text() == "done: v0001"

    # Nothing changed since v0001: the poll that saw the job end turned Train off, the reason beside it (pressing it
    # again trained ~170 s, then failed as "the same model as v0001"). Other epochs would make another model: on.
    train, why = page.get_by_test_id("train"), page.get_by_test_id("train-why")
    why.filter(has_text="Nothing changed since v0001: it learned from this same drive with 2 epochs.").wait_for()
    assert train.is_disabled()
    assert page.locator('[data-testid=version-row][data-version="v0001"]').is_visible()  # no reload needed
    reason, button = why.bounding_box(), train.bounding_box()
    assert reason["x"] > button["x"] + button["width"] - 1 and abs(reason["y"] - button["y"]) < 30  # beside it
    page.set_viewport_size({"width": 1920, "height": 1080})
    page.get_by_test_id("train-form").scroll_into_view_if_needed()
    page.screenshot(path=str(SCREENSHOTS / "booth-train-off-1920.png"))
    page.fill("input[name=epochs]", "3")
    page.wait_for_function("() => !document.querySelector('[data-testid=train]').disabled", timeout=10_000)
    assert why.count() == 0
    page.fill("input[name=epochs]", "2")
    why.wait_for(timeout=10_000)
    assert train.is_disabled()
    page.set_viewport_size({"width": 390, "height": 844})
    page.get_by_test_id("train-form").scroll_into_view_if_needed()
    assert page.evaluate("document.documentElement.scrollWidth") <= 390
    page.screenshot(path=str(SCREENSHOTS / "booth-train-off-390.png"))
    page.set_viewport_size({"width": 1280, "height": 720})
    page.goto(app_url + "/booth")  # laid out afresh: a layout left from the phone width moved the link under a click

    # The autonomous run of v0001 on the oval, with its metrics.
    job.get_by_test_id("job-run").click()
    page.wait_for_url(f"{app_url}/booth/runs/*")
    assert "Autonomous run of v0001 on drem_oval" in page.locator("h1").inner_text()
    assert page.get_by_test_id("run-status").inner_text() == "FINALISED"
    completion = page.get_by_test_id("metric-completion").inner_text()
    assert completion.endswith(" %")

    # v0001 is the racer's version (scrutineered), can be made active, and the registry shows it with its metrics.
    page.goto(app_url + "/booth")
    version = page.locator('[data-testid=version-row][data-version="v0001"]')
    assert "AVAILABLE" in version.inner_text() and "laps completed" in version.inner_text()
    version.get_by_test_id("make-active").click()
    version.get_by_test_id("active-version").wait_for()
    page.goto(app_url + "/models/registry")
    row = page.locator('.registry-row[data-model="v0001"]')
    assert f"drem_oval: {float(completion.removesuffix(' %')):.0f} % complete" in row.inner_text()
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "booth-registry.png"), full_page=True)

    # Staff send the racer's active version to a car from the booth (asked first unless it passed scrutineering).
    operator = create_user(live_stack, f"booth.op.{secrets.token_hex(3)}", "operator")
    token = access_token(live_stack, operator)
    fleet = call(app_url, "POST", "/api/fleets", token=token, body={"name": f"Booth {operator}"}, expect=201)
    hostname = f"booth-car-{secrets.token_hex(2)}"
    code = call(app_url, "POST", "/api/devices/activation-codes", token=token, expect=201,
                body={"fleet_id": fleet["fleet_id"], "hostname": hostname, "device_kind": "car"})["code"]
    call(app_url, "POST", "/api/devices/activate", expect=201,
         body={"code": code, "hostname": hostname, "device_kind": "car"})
    page.context.clear_cookies()
    sign_in(page, app_url, operator)
    page.goto(app_url + "/booth?everyone=true")
    active = page.locator(f'[data-testid=active-row][data-racer="{username}"]')
    assert "v0001" in active.inner_text()
    active.get_by_role("combobox").select_option(label=f"{hostname} (offline)")
    active.get_by_test_id("send-to-car").click()
    status = page.get_by_test_id("car-status")
    status.get_by_text("Models sent to the car.").or_(status.get_by_test_id("send-anyway")).wait_for()
    if status.get_by_test_id("send-anyway").count():
        assert f"{username} – v0001:" in status.get_by_test_id("scrutiny-warning").inner_text()
        status.get_by_test_id("send-anyway").click()
        status.get_by_text("Models sent to the car.").wait_for()
    sent = status.locator('[data-testid=car-model-row][data-model-name="v0001"]')
    assert sent.get_by_test_id("car-model-status").inner_text() == "assigned"
    page.screenshot(path=str(ARTIFACTS / "booth-send-to-car.png"), full_page=True)
