"""The booth's top-down map, as a visitor sees it: beside the camera while driving, the car moves on the track, its
trail grows and a red mark appears where it left the track; the saved run's page shows the same drive. Screenshots at
1920×1080 and 390×844 go to docs/screenshots/ (booth-map-*)."""
from __future__ import annotations

import secrets
from pathlib import Path
from typing import Any

import pytest

from tests.browser.console_api import create_user, sign_in

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "docs" / "screenshots"
TRAIL_AT_LEAST = ("n => document.querySelector('[data-map=trail]').getAttribute('points').trim()"
                  ".split(/\\s+/).length >= n")
OFF_MARKS_AT_LEAST = "n => document.querySelectorAll('[data-map=off] circle').length >= n"


def state(page: Any, testid: str) -> str:
    return page.get_by_test_id(testid).inner_text()


def test_the_map_follows_the_car_while_driving_and_shows_the_saved_run(app_url: str, live_stack: Any,
                                                                        page: Any) -> None:
    page.set_viewport_size({"width": 1920, "height": 1080})
    username = create_user(live_stack, f"map.{secrets.token_hex(3)}", "racer")
    sign_in(page, app_url, username)
    page.goto(app_url + "/booth/drive/drem_oval")
    car = page.locator('[data-map="car"]')
    at_start = (car.get_attribute("cx"), car.get_attribute("cy"))
    page.get_by_test_id("drive-start").click()
    page.get_by_test_id("drive-status").filter(has_text="Recording").wait_for()
    page.keyboard.down("ArrowUp")
    page.wait_for_function(TRAIL_AT_LEAST, arg=25, timeout=30_000)  # the trail grows as frames arrive
    assert (car.get_attribute("cx"), car.get_attribute("cy")) != at_start  # the car moved on the map
    page.keyboard.down("ArrowRight")  # full lock at speed on the straight: off the track
    page.wait_for_function(OFF_MARKS_AT_LEAST, arg=1, timeout=30_000)
    page.keyboard.up("ArrowRight")
    page.keyboard.up("ArrowUp")
    assert int(state(page, "drive-frames")) > 25
    assert page.get_by_test_id("drive-map").is_visible() and page.get_by_test_id("drive-frame").is_visible()
    camera, drawn = page.get_by_test_id("drive-frame").bounding_box(), page.get_by_test_id("drive-map").bounding_box()
    assert drawn["x"] > camera["x"] + camera["width"] - 1 and abs(drawn["y"] - camera["y"]) < 40  # beside it
    page.screenshot(path=str(SCREENSHOTS / "booth-map-drive-1920.png"))

    page.get_by_test_id("drive-finish").click()
    page.wait_for_url(f"{app_url}/booth/runs/*")
    run_url = page.url
    saved = page.get_by_test_id("run-map")
    assert saved.locator(".map-off").count() >= 1  # where it left the track, on the saved run too
    assert len(saved.locator('[data-map="trail"]').get_attribute("points").split()) > 25
    page.screenshot(path=str(SCREENSHOTS / "booth-map-run-1920.png"), full_page=True)

    page.set_viewport_size({"width": 390, "height": 844})
    page.goto(run_url)
    assert page.evaluate("document.documentElement.scrollWidth") <= 390  # nothing off the side of the phone
    page.get_by_test_id("run-map").scroll_into_view_if_needed()
    page.screenshot(path=str(SCREENSHOTS / "booth-map-run-390.png"), full_page=True)
    page.goto(app_url + "/booth/drive/drem_oval")
    assert page.get_by_test_id("drive-map").is_visible()
    assert page.evaluate("document.documentElement.scrollWidth") <= 390
    page.screenshot(path=str(SCREENSHOTS / "booth-map-drive-390.png"), full_page=True)
