"""Issue 35 in Chromium: the racing car's camera on the stream overlay (picture in picture, clear of the lower third)
and on the staff's Cars page, fed end to end by a stock DeepRacer (the tests' fake console, its MJPEG route) through
the car's video relay and the live server; staff set a car's camera on the Cars page and a fleet's on the Fleets page.
Screenshots at 1920×1080 and 390×844 go to docs/screenshots/."""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drem_cars.drivers.deepracer_console import DeepRacerConsole
from drem_cars.video_relay import VideoRelay, VideoSettings
from drem_cars.video_sources import ConsoleCamera
from tests.browser.console_api import access_token, call, create_user, sign_in
from tests.browser.painted import painted
from tests.cars.fake_deepracer_console import FakeConsole

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "docs" / "screenshots"
SIZES = ({"width": 1920, "height": 1080}, {"width": 390, "height": 844})


@pytest.fixture(scope="module")
def racing_car(live_stack: Any) -> Iterator[dict[str, Any]]:
    url = live_stack.url
    operator = create_user(live_stack, "eye-op", "operator")
    token = access_token(live_stack, operator)
    racer = create_user(live_stack, "eye-racer", "racer")
    fleet = call(url, "POST", "/api/fleets", token=token, body={"name": "Eye fleet"}, expect=201)
    event = call(url, "POST", "/api/events", token=token, expect=201, body={
        "name": "Car's Eye Cup", "event_type": "AWS_SUMMIT", "date": "2026-06-02", "country_code": "SE",
        "race_config": {"race_time_min": 3}, "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"]}]})
    code = call(url, "POST", "/api/devices/activation-codes", token=token, expect=201,
                body={"fleet_id": fleet["fleet_id"], "hostname": "eye-car", "device_kind": "car"})["code"]
    credential = call(url, "POST", "/api/devices/activate", expect=201,
                      body={"code": code, "hostname": "eye-car", "device_kind": "car"})["credential"]
    eid = event["event_id"]
    race = call(url, "POST", f"/api/events/{eid}/races", token=token, expect=201,
                body={"track_id": "1", "racer_username": racer, "car": "eye-car"})
    with FakeConsole() as console:
        camera = ConsoleCamera(DeepRacerConsole(console.url, "car-password"))
        relay = VideoRelay(live_stack.live_url, credential, camera, VideoSettings(fps=15), demand_wait_s=5)
        relay.start()
        try:
            call(url, "POST", f"/api/events/{eid}/races/{race['race_id']}/commands", token=token,
                 body={"kind": "start"})
            yield {"event_id": eid, "race_id": race["race_id"], "token": token, "operator": operator,
                   "fleet_id": fleet["fleet_id"]}
        finally:
            relay.stop()


def frames_painted(page: Any) -> int:
    return int(page.locator("[data-car-eye]").get_attribute("data-frames") or 0)


def shoot(page: Any, name: str) -> None:
    for size in SIZES:
        page.set_viewport_size(size)
        painted(page)  # the resized layout (and a board's paging) on screen before the screenshot
        page.screenshot(path=str(SCREENSHOTS / f"{name}-{size['width']}x{size['height']}.png"))


def test_the_overlay_shows_the_racing_cars_camera_frame_after_frame_above_the_lower_third(
        chromium: Any, racing_car: dict[str, Any], app_url: str) -> None:
    page = chromium.new_context(viewport=SIZES[0]).new_page()
    page.goto(f"{app_url}/overlay/{racing_car['event_id']}?trackId=1&chroma=true&carEye=true")
    page.wait_for_function("() => Number(document.querySelector('[data-car-eye]').dataset.frames) >= 3",
                           timeout=30_000)
    first = frames_painted(page)
    # Frames keep arriving: ten more painted (at 15 fps, under a second on a quiet machine).
    page.wait_for_function(f"() => Number(document.querySelector('[data-car-eye]').dataset.frames) >= {first + 10}",
                           timeout=30_000)
    eye = page.locator("[data-car-eye]")
    assert eye.is_visible()
    box, bar = eye.bounding_box(), page.locator("[data-testid=lower-third]").bounding_box()
    assert box is not None and bar is not None
    assert box["y"] + box["height"] <= 1080 * 2 / 3  # never in the lower third
    assert box["y"] + box["height"] < bar["y"]
    # At every animation frame for a second, the picture shown is a whole camera frame: never an empty one while the
    # next frame loads.
    widths = page.evaluate("""() => new Promise(done => {
        const widths = [], until = performance.now() + 1000;
        (function look() {
            widths.push(document.querySelector('[data-car-eye] img').naturalWidth);
            if (performance.now() < until) { requestAnimationFrame(look); } else { done(widths); }
        })();
    })""")
    assert len(widths) > 10 and set(widths) == {480}
    shoot(page, "car-eye-overlay")
    page.context.close()


def test_an_overlay_link_without_the_option_shows_no_camera(chromium: Any, racing_car: dict[str, Any],
                                                            app_url: str) -> None:
    page = chromium.new_context(viewport=SIZES[0]).new_page()
    page.goto(f"{app_url}/overlay/{racing_car['event_id']}?trackId=1")
    page.locator("[data-testid=lower-third]").wait_for()
    assert page.locator("[data-car-eye]").count() == 0
    page.context.close()


def test_staff_see_each_cars_camera_on_the_cars_page(chromium: Any, racing_car: dict[str, Any],
                                                     app_url: str) -> None:
    page = chromium.new_context(viewport=SIZES[0]).new_page()
    sign_in(page, app_url, racing_car["operator"])
    page.goto(f"{app_url}/console/cars")
    thumbnail = page.locator("[data-testid=camera-eye-car] img")
    thumbnail.wait_for()
    page.wait_for_function("() => document.querySelector('[data-testid=camera-eye-car] img').naturalWidth > 0",
                           timeout=30_000)
    assert page.locator("[data-testid=camera-eye-car]").get_attribute("target") == "_blank"  # full size on click
    shoot(page, "car-eye-cars-page")
    page.context.close()


def test_the_big_screen_shows_it_beside_the_board_and_the_commentator_sees_it(
        chromium: Any, racing_car: dict[str, Any], app_url: str) -> None:
    page = chromium.new_context(viewport=SIZES[0]).new_page()
    page.goto(f"{app_url}/leaderboard/{racing_car['event_id']}?track=1&carEye=true")
    page.wait_for_function("() => Number(document.querySelector('[data-car-eye]').dataset.frames) >= 3",
                           timeout=30_000)
    eye, board = page.locator("[data-car-eye]").bounding_box(), page.locator(".public-board").bounding_box()
    assert eye is not None and board is not None
    assert board["x"] + board["width"] <= eye["x"]  # beside the board, not over it
    sign_in(page, app_url, racing_car["operator"])
    page.goto(f"{app_url}/commentator/{racing_car['event_id']}?track=1")
    page.wait_for_function("() => Number(document.querySelector('[data-car-eye]').dataset.frames) >= 3",
                           timeout=30_000)
    page.context.close()


def test_the_camera_falls_back_to_nothing_when_the_race_ends(chromium: Any, racing_car: dict[str, Any],
                                                             app_url: str) -> None:
    page = chromium.new_context(viewport=SIZES[0]).new_page()
    page.goto(f"{app_url}/overlay/{racing_car['event_id']}?trackId=1&carEye=true")
    page.wait_for_function("() => Number(document.querySelector('[data-car-eye]').dataset.frames) >= 3",
                           timeout=30_000)
    path = f"/api/events/{racing_car['event_id']}/races/{racing_car['race_id']}/commands"
    for kind in ("end", "submit"):
        call(app_url, "POST", path, token=racing_car["token"], body={"kind": kind})
    page.wait_for_function("() => document.querySelector('[data-car-eye]').hidden", timeout=30_000)
    assert not page.locator("[data-car-eye]").is_visible()
    page.context.close()


def test_staff_set_a_cars_camera_on_the_cars_page_and_the_car_sends_at_it(chromium: Any, racing_car: dict[str, Any],
                                                                          app_url: str) -> None:
    page = chromium.new_context(viewport=SIZES[0]).new_page()
    sign_in(page, app_url, racing_car["operator"])
    page.goto(f"{app_url}/console/cars")
    form = page.locator("[data-testid=video-eye-car]")
    form.locator("select[name=fps]").select_option("10")
    form.locator("select[name=size]").select_option("320x240")
    form.locator("select[name=view]").select_option("model")
    form.locator("button[type=submit]").click()
    page.get_by_text("Camera settings saved").wait_for()
    form = page.locator("[data-testid=video-eye-car]")  # the page after the redirect shows what was chosen
    assert form.locator("select[name=view]").input_value() == "model"
    assert form.locator("select[name=fps]").input_value() == "10"
    # The preview thumbnail turns into the model's own view: 160×120 (the relay took the setting up by itself).
    page.wait_for_function(
        "() => { const i = document.querySelector('[data-testid=camera-eye-car] img');"
        " return i && i.naturalWidth === 160 && i.naturalHeight === 120; }", timeout=60_000)
    shoot(page, "car-eye-cars-page-settings")
    page.context.close()


def test_staff_set_a_whole_fleets_camera_on_the_fleets_page_and_its_car_shows_it_on_the_cars_page(
        chromium: Any, racing_car: dict[str, Any], app_url: str) -> None:
    page = chromium.new_context(viewport=SIZES[0]).new_page()
    sign_in(page, app_url, racing_car["operator"])
    page.goto(f"{app_url}/console/fleets")
    form = page.locator(f"[data-testid=fleet-video-{racing_car['fleet_id']}]")
    form.locator("select[name=fps]").select_option("20")
    form.locator("select[name=size]").select_option("640x480")
    form.locator("select[name=view]").select_option("camera")
    form.locator("button[type=submit]").click()
    page.get_by_text("saved for the 1 car of Eye fleet").wait_for()
    assert page.get_by_text("Its car is set to 20 fps, 640×480, camera.").is_visible()
    shoot(page, "car-eye-fleets-page")
    page.goto(f"{app_url}/console/cars")
    form = page.locator("[data-testid=video-eye-car]")  # the fleet's car shows what was chosen for the fleet
    assert form.locator("select[name=fps]").input_value() == "20"
    assert form.locator("select[name=size]").input_value() == "640x480"
    assert form.locator("select[name=view]").input_value() == "camera"
    page.context.close()
