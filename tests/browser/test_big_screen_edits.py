"""Issue 31: footer and sponsor edits reached an open big screen only after a reload. Here the big screen is open (on
the projector, pushed by the live server; on a phone, polling the app because its stream is refused) while staff edit
the event in the console: the new sponsor, footer, name and logo appear on both without a reload."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from tests.browser.console_api import access_token, call, create_user, sign_in, submitted_race
from tests.browser.test_event_logo import BIG_SCREEN, PHONE, sponsor_logo
from tests.browser.test_live_push import wait_until

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "big-screen"


def test_staff_edits_of_sponsor_footer_and_logo_reach_open_big_screens(chromium: Any, live_stack: Any, app_url: str,
                                                                       browser_errors: Any, tmp_path: Path) -> None:
    create_user(live_stack, "screen-editor", "operator")
    create_user(live_stack, "screen-racer", "racer")
    token = access_token(live_stack, "screen-editor")
    event_id = call(app_url, "POST", "/api/events", token=token, expect=201, body={
        "name": "Screen Cup", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-06-02", "country_code": "SE",
        "tracks": [{"track_id": "1", "leaderboard_title": "Main stage"}]})["event_id"]
    submitted_race(app_url, token, event_id, "screen-racer", [9_120])
    board_url = f"{app_url}/leaderboard/{event_id}?summary_seconds=0"

    projector = chromium.new_context(viewport=BIG_SCREEN).new_page()
    polls: list[str] = []
    projector.on("request", lambda request: polls.append(request.url) if "/live?" in request.url else None)
    projector.goto(board_url)
    wait_until(projector, "() => !!window.dremLiveStream && window.dremLiveStream.readyState === 1")
    assert projector.get_by_test_id("board-sponsor").is_hidden()
    phone = chromium.new_context(viewport=PHONE).new_page()
    browser_errors.allow(r"/live/leaderboard/.*status of 503")  # the phone's stream, refused on purpose
    phone.route(re.compile(r".*/live/leaderboard/.*"), lambda route: route.fulfill(status=503, body="full"))
    phone.goto(board_url)
    assert "Follow the race #AWSDeepRacer" in phone.get_by_test_id("board-footer").inner_text()

    staff = chromium.new_context(viewport=BIG_SCREEN).new_page()
    sign_in(staff, app_url, "screen-editor")
    staff.goto(f"{app_url}/console/events/{event_id}/edit")
    staff.fill("#name", "Screen Cup Finals")
    staff.fill("#sponsor", "Acme Robotics")
    staff.fill("#track-1-footer", "Race again at the Acme booth")
    staff.get_by_role("button", name="Save event").click()
    staff.wait_for_url(re.compile(r".*/console/events\?.*"))
    staff.goto(f"{app_url}/console/events/{event_id}/edit")
    staff.set_input_files("#logo-file", str(sponsor_logo(tmp_path / "acme.png")))
    staff.get_by_role("button", name="Upload logo").click()
    staff.get_by_test_id("notice").wait_for()

    for screen in (projector, phone):  # no reload: the live region brings the edits
        screen.wait_for_selector("[data-testid=board-sponsor]:has-text('Acme Robotics')", timeout=20_000)
        screen.wait_for_selector("[data-testid=board-footer]:has-text('Race again at the Acme booth')")
        screen.wait_for_selector("[data-testid=board-title]:has-text('Screen Cup Finals')")
        screen.wait_for_selector("[data-testid=board-logo]", timeout=20_000)
        wait_until(screen, "() => document.querySelector('[data-testid=board-logo]').complete")
        assert "Main stage" in screen.get_by_test_id("board-subtitle").inner_text()
        assert screen.locator(".board-row[data-racer='screen-racer']").count() == 1  # the rows stay
        assert screen.locator("#board-notes").count() == 1 and screen.locator("#board-sponsor").count() == 1
    assert polls == [], polls  # the projector's edits came by push
    assert projector.evaluate("() => document.documentElement.scrollWidth") <= BIG_SCREEN["width"]
    assert phone.evaluate("() => document.documentElement.scrollWidth") <= PHONE["width"]
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    projector.screenshot(path=str(SCREENSHOTS / "edited-live-1920x1080.png"))
    phone.screenshot(path=str(SCREENSHOTS / "edited-live-390x844.png"), full_page=True)
    for page in (projector, phone, staff):
        page.context.close()
