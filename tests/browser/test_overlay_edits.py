"""Issue 31: an edit of the event's name or logo reached an open stream overlay (an OBS browser source nobody reloads
during a stream) only after a reload. Here the overlay is open (pushed by the live server, and a second one polling
the app because its stream is refused) while staff rename the event and upload its logo: both overlays show them
without a reload, and the race on the overlay stays."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from tests.browser.console_api import access_token, call, create_user, sign_in, submitted_race
from tests.browser.test_event_logo import BIG_SCREEN, sponsor_logo
from tests.browser.test_live_push import wait_until

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "overlay"


def test_a_renamed_event_and_a_new_logo_reach_an_open_overlay(chromium: Any, live_stack: Any, app_url: str,
                                                              browser_errors: Any, tmp_path: Path) -> None:
    create_user(live_stack, "overlay-op", "operator")
    create_user(live_stack, "overlay-racer", "racer")
    token = access_token(live_stack, "overlay-op")
    event_id = call(app_url, "POST", "/api/events", token=token, expect=201, body={
        "name": "Overlay Cup", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-06-06", "country_code": "SE",
        "tracks": [{"track_id": "1"}]})["event_id"]
    submitted_race(app_url, token, event_id, "overlay-racer", [9_120])
    overlay_url = f"{app_url}/overlay/{event_id}?track=1"

    streamed = chromium.new_context(viewport=BIG_SCREEN).new_page()
    polls: list[str] = []
    streamed.on("request", lambda request: polls.append(request.url) if "/live?" in request.url else None)
    streamed.goto(overlay_url)
    wait_until(streamed, "() => !!window.dremLiveStream && window.dremLiveStream.readyState === 1")
    polled = chromium.new_context(viewport=BIG_SCREEN).new_page()
    browser_errors.allow(r"/live/overlay/.*status of 503")  # the second overlay's stream, refused on purpose
    polled.route(re.compile(r".*/live/overlay/.*"), lambda route: route.fulfill(status=503, body="full"))
    polled.goto(overlay_url)
    for overlay in (streamed, polled):
        assert overlay.get_by_test_id("overlay-title").inner_text() == "Overlay Cup"
        assert overlay.get_by_test_id("overlay-logo").count() == 0
        assert "overlay-racer" in overlay.locator("#overlay-live").inner_text()

    staff = chromium.new_context(viewport=BIG_SCREEN).new_page()
    sign_in(staff, app_url, "overlay-op")
    staff.goto(f"{app_url}/console/events/{event_id}/edit")
    staff.fill("#name", "Overlay Cup Finals")
    staff.get_by_role("button", name="Save event").click()
    staff.wait_for_url(re.compile(r".*/console/events\?.*"))
    staff.goto(f"{app_url}/console/events/{event_id}/edit")
    staff.set_input_files("#logo-file", str(sponsor_logo(tmp_path / "acme.png")))
    staff.get_by_role("button", name="Upload logo").click()
    staff.get_by_test_id("notice").wait_for()

    for overlay in (streamed, polled):  # no reload: the live region brings the edits
        overlay.wait_for_selector("[data-testid=overlay-title]:text-is('Overlay Cup Finals')", timeout=20_000)
        overlay.wait_for_selector("[data-testid=overlay-logo]", timeout=20_000)
        wait_until(overlay, "() => document.querySelector('[data-testid=overlay-logo]').complete")
        assert overlay.locator("#overlay-title").count() == 1 and overlay.locator("#overlay-logo-slot").count() == 1
        assert overlay.locator("#overlay-live").count() == 1  # the race region stays, with the racer
        assert "overlay-racer" in overlay.locator("#overlay-live").inner_text()
    assert polls == [], polls  # the streamed overlay's edits came by push
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    streamed.screenshot(path=str(SCREENSHOTS / "edited-live-1920x1080.png"))
    for page in (streamed, polled, staff):
        page.context.close()
