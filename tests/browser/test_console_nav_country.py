"""The console in a real browser: the country picker found by typing (refused text stays, with its message), the
nav grouped by role folding behind "Menu" on a phone, and a success message after a change. Screenshots of the
events page and the profile's picker at 1920x1080 and 390x844 go to test-artifacts/console/ (docs/screenshots/
holds the reviewed copies)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.browser.console_api import create_user, sign_in

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "console"
SIZES = ({"width": 1920, "height": 1080}, {"width": 390, "height": 844})


def _shot(page: Any, name: str, size: dict[str, int]) -> None:
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SCREENSHOTS / f"{name}-{size['width']}x{size['height']}.png"))


def test_a_racer_finds_their_country_by_typing_its_name_and_saves_it(app_url, live_stack, page):
    create_user(live_stack, "picker-racer", "racer")
    sign_in(page, app_url, "picker-racer")
    page.goto(app_url + "/console/profile")
    picker = page.get_by_role("combobox", name="Country")  # a text input with a list: a combobox to screen readers

    picker.click()
    page.keyboard.press("Control+A")
    page.keyboard.type("Narnia")
    page.get_by_role("button", name="Save profile").click()
    assert "No country is called 'Narnia'" in page.locator("#country_code-error").inner_text()
    assert picker.input_value() == "Narnia" and picker.get_attribute("aria-invalid") == "true"

    picker.click()
    page.keyboard.press("Control+A")
    page.keyboard.type("norway")
    page.keyboard.press("Enter")  # Enter in the field submits the form, as in any text input
    page.get_by_test_id("notice").wait_for()
    assert page.get_by_test_id("notice").inner_text() == "Your profile is saved; the leaderboards show it now."
    assert picker.input_value() == "Norway (NO)"
    page.reload()
    assert page.get_by_role("combobox", name="Country").input_value() == "Norway (NO)"


def test_the_nav_groups_by_role_and_folds_behind_menu_on_a_phone(app_url, live_stack, chromium):
    create_user(live_stack, "nav-racer", "racer")
    create_user(live_stack, "nav-admin", "admin")
    context = chromium.new_context(viewport=SIZES[1])
    page = context.new_page()
    sign_in(page, app_url, "nav-racer")
    links = page.get_by_test_id("nav-links")
    assert not links.is_visible()  # folded on a phone
    page.focus("#nav-toggle")
    page.keyboard.press("Space")  # the Menu toggle works from the keyboard
    assert links.is_visible()
    assert [group.inner_text() for group in page.locator(".nav-group-title").all()] == ["RACER", "RESULTS"]
    assert links.get_by_role("link", name="Users").count() == 0
    box = links.get_by_role("link", name="My models").bounding_box()
    assert box is not None and box["height"] >= 32  # a row to hit with a thumb
    context.close()

    context = chromium.new_context(viewport=SIZES[0])
    page = context.new_page()
    sign_in(page, app_url, "nav-admin")
    links = page.get_by_test_id("nav-links")
    assert links.is_visible() and not page.locator(".nav-toggle-label").is_visible()
    assert [group.inner_text() for group in page.locator(".nav-group-title").all()] == [
        "RACER", "REGISTRATION", "RACE CONTROL", "ADMIN", "RESULTS"]
    page.get_by_role("list", name="Race control").get_by_role("link", name="Fleets").click()
    page.fill("#name", "Nav fleet")
    page.get_by_role("button", name="Create fleet").click()
    page.wait_for_url(app_url + "/console/fleets?done=fleet-created")
    assert page.get_by_test_id("notice").inner_text() == "Fleet created."
    context.close()


def test_screenshots_of_the_events_page_and_the_country_search(app_url, live_stack, chromium):
    create_user(live_stack, "shot-admin", "admin")
    for size in SIZES:
        context = chromium.new_context(viewport=size)
        page = context.new_page()
        sign_in(page, app_url, "shot-admin")
        page.goto(app_url + "/console/events")
        _shot(page, "console-events", size)
        if size["width"] < 600:
            page.get_by_text("Menu").click()
            page.get_by_test_id("nav-links").wait_for()
            _shot(page, "console-menu-open", size)
        page.goto(app_url + "/console/profile")
        page.get_by_role("combobox", name="Country").click()
        page.keyboard.type("swe")
        _shot(page, "console-profile-country-search", size)
        context.close()
