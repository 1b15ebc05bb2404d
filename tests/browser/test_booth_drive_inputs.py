"""The booth's drive page with the inputs a visitor brings besides a keyboard: a phone's touch buttons (real touch
events from Chromium's input pipeline, two fingers at once) and a gamepad (W3C "standard" mapping). What the racer
would notice is what the run recorded: the controls.jsonl the trainer learns from says the car sped up and turned
the way the visitor asked."""
from __future__ import annotations

import json
import secrets
from pathlib import Path
from typing import Any

import pytest
import requests

from chalicelib.domain.booth_drive import FULL_THROTTLE_SPEED
from drem_sim.physics import CarSpec
from tests.browser.console_api import access_token, create_user, sign_in

pytestmark = pytest.mark.browser

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"

# navigator.getGamepads() as Chromium answers it for a pad with the "standard" mapping
# (https://w3c.github.io/gamepad/#remapping): axes[0] left stick X (-1 left … +1 right), axes[3] right stick Y,
# buttons[6]/[7] the left/right triggers with an analogue `value` 0..1. The page reads only these fields.
FAKE_PAD = """
window.__pad = {axes: [0, 0, 0, 0], buttons: Array.from({length: 17}, () => ({pressed: false, value: 0}))};
navigator.getGamepads = () => [{id: "drem test pad (STANDARD GAMEPAD)", index: 0, connected: true,
                               mapping: "standard", timestamp: performance.now(),
                               axes: window.__pad.axes, buttons: window.__pad.buttons}, null, null, null];
"""


def frames_reach(page: Any, count: int) -> None:
    page.wait_for_function(
        "n => Number(document.querySelector('[data-testid=drive-frames]').textContent) >= n", arg=count)


def recorded_controls(app_url: str, token: str, run_id: str) -> list[dict[str, Any]]:
    reply = requests.get(f"{app_url}/api/runs/{run_id}/artifacts/controls.jsonl", timeout=15,
                         headers={"Authorization": f"Bearer {token}"})
    assert reply.status_code == 200, reply.text
    return [json.loads(line) for line in reply.text.splitlines() if line]


def finish(page: Any, app_url: str) -> str:
    run_id = page.get_by_test_id("booth-drive").get_attribute("data-run-id")
    page.get_by_test_id("drive-finish").click()
    page.wait_for_url(f"{app_url}/booth/runs/*")
    assert page.get_by_test_id("run-status").inner_text() == "FINALISED"
    return run_id


@pytest.fixture
def phone(chromium: Any):
    context = chromium.new_context(viewport={"width": 390, "height": 844}, device_scale_factor=3,
                                   is_mobile=True, has_touch=True)
    context.set_default_timeout(10_000)
    yield context.new_page()
    context.close()


def test_a_phone_drives_with_two_fingers_on_the_touch_buttons(app_url: str, live_stack: Any, phone: Any) -> None:
    username = create_user(live_stack, f"touch.{secrets.token_hex(3)}", "racer")
    sign_in(phone, app_url, username)
    phone.goto(app_url + "/booth/drive/drem_oval")
    assert phone.evaluate("document.documentElement.scrollWidth") <= 390  # nothing off the side of the phone
    phone.get_by_test_id("drive-start").click()
    phone.get_by_test_id("drive-status").filter(has_text="Recording").wait_for()
    # Where the buttons are now, on the screen (tapping Start may have scrolled the page).
    buttons = {name: phone.locator(f'.drive-touch [data-control="{name}"]').bounding_box()
               for name in ("left", "throttle", "brake", "right")}
    assert all(box["width"] >= 44 and box["height"] >= 44 for box in buttons.values()), buttons  # thumb-sized
    assert all(box["y"] >= 0 and box["y"] + box["height"] <= 844 for box in buttons.values()), buttons  # on screen
    touch = phone.context.new_cdp_session(phone)

    def finger(name: str, finger_id: int) -> dict[str, float]:
        box = buttons[name]
        return {"x": box["x"] + box["width"] / 2, "y": box["y"] + box["height"] / 2, "id": finger_id}

    # Hold ▲ with one thumb, then press ◀ with the other as well, then lift both.
    touch.send("Input.dispatchTouchEvent", {"type": "touchStart", "touchPoints": [finger("throttle", 1)]})
    frames_reach(phone, 30)
    touch.send("Input.dispatchTouchEvent", {"type": "touchStart",
                                            "touchPoints": [finger("throttle", 1), finger("left", 2)]})
    frames_reach(phone, 45)
    touch.send("Input.dispatchTouchEvent", {"type": "touchEnd", "touchPoints": []})
    frames_reach(phone, 55)
    ARTIFACTS.mkdir(exist_ok=True)
    phone.screenshot(path=str(ARTIFACTS / "booth-drive-390x844.png"))
    run_id = finish(phone, app_url)

    rows = recorded_controls(app_url, access_token(live_stack, username), run_id)
    assert max(r["speed"] for r in rows) > 0, "holding ▲ never asked for speed"
    assert any(r["steering_angle"] > 0 and r["speed"] > 0 for r in rows), "◀ with ▲ never steered left"
    assert all(r["steering_angle"] >= 0 for r in rows), "the car steered right although nobody pressed ▶"
    assert rows[-1]["speed"] == 0 and rows[-1]["steering_angle"] == 0, "lifting both thumbs did not let go"
    assert rows[-1]["progress"] > rows[0]["progress"], "the car did not move along the track"


def test_a_gamepad_steers_with_its_stick_and_accelerates_with_its_trigger(app_url: str, live_stack: Any,
                                                                          page: Any) -> None:
    username = create_user(live_stack, f"pad.{secrets.token_hex(3)}", "racer")
    page.add_init_script(FAKE_PAD)
    sign_in(page, app_url, username)
    page.goto(app_url + "/booth/drive/drem_oval")
    page.get_by_test_id("drive-start").click()
    page.get_by_test_id("drive-status").filter(has_text="Recording").wait_for()

    page.evaluate("window.__pad.buttons[7].value = 0.5; window.__pad.buttons[7].pressed = true")  # half throttle
    frames_reach(page, 20)
    page.evaluate("window.__pad.axes[0] = 0.6")  # stick 60 % to the right
    frames_reach(page, 35)
    page.evaluate("window.__pad.axes[0] = 0.03")  # a worn stick resting just off centre: the dead zone ignores it
    frames_reach(page, 45)
    page.evaluate("window.__pad.buttons[7].value = 0; window.__pad.buttons[7].pressed = false")
    frames_reach(page, 50)
    run_id = finish(page, app_url)

    rows = recorded_controls(app_url, access_token(live_stack, username), run_id)
    # Proportional, not on/off: half the trigger asks half of full speed, 60 % of the stick 60 % of full lock.
    asked_speeds = sorted({r["speed"] for r in rows if r["speed"] > 0})
    assert asked_speeds == pytest.approx([0.5 * FULL_THROTTLE_SPEED]), asked_speeds
    steered = sorted({r["steering_angle"] for r in rows if r["steering_angle"] != 0})
    assert steered == pytest.approx([-0.6 * CarSpec().max_steering_deg]), steered  # right is negative
    assert rows[-1]["speed"] == 0 and rows[-1]["steering_angle"] == 0, "releasing the trigger did not stop asking"
    assert sum(1 for r in rows if r["steering_angle"] != 0) >= 10  # the stick's whole hold, not a blip
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "booth-drive-gamepad-1920x1080.png"))
