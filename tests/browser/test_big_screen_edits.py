"""Issue 31: footer and sponsor edits reached an open big screen only after a reload. Here the big screen is open (on
the projector, pushed by the live server; on a phone, polling the app because its stream is refused) while staff edit
the event in the console: the new sponsor, footer, name and logo appear on both without a reload."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.browser.screen_edits import edit_event, first_shown_by_push, pushed_and_polled, raced_event
from tests.browser.test_event_logo import BIG_SCREEN, PHONE
from tests.browser.test_live_push import wait_until

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "big-screen"


def test_staff_edits_of_sponsor_footer_and_logo_reach_open_big_screens(chromium: Any, live_stack: Any, app_url: str,
                                                                       browser_errors: Any, tmp_path: Path) -> None:
    event_id = raced_event(live_stack, app_url, "screen-editor", "screen-racer", "Screen Cup",
                           {"track_id": "1", "leaderboard_title": "Main stage"})
    projector, polls, phone = pushed_and_polled(chromium, f"{app_url}/leaderboard/{event_id}?summary_seconds=0",
                                                "leaderboard", browser_errors, PHONE)
    assert projector.get_by_test_id("board-sponsor").is_hidden()
    assert "Follow the race #AWSDeepRacer" in phone.get_by_test_id("board-footer").inner_text()
    edit_event(chromium, app_url, "screen-editor", event_id, {
        "#name": "Screen Cup Finals", "#sponsor": "Acme Robotics", "#track-1-footer": "Race again at the Acme booth"},
        tmp_path)

    for screen in (projector, phone):  # no reload: the live region brings the edits
        screen.wait_for_selector("[data-testid=board-sponsor]:has-text('Acme Robotics')", timeout=20_000)
        screen.wait_for_selector("[data-testid=board-footer]:has-text('Race again at the Acme booth')")
        screen.wait_for_selector("[data-testid=board-title]:has-text('Screen Cup Finals')")
        screen.wait_for_selector("[data-testid=board-logo]", timeout=20_000)
        wait_until(screen, "() => document.querySelector('[data-testid=board-logo]').complete")
        assert "Main stage" in screen.get_by_test_id("board-subtitle").inner_text()
        assert screen.locator(".board-row[data-racer='screen-racer']").count() == 1  # the rows stay
        assert screen.locator("#board-notes").count() == 1 and screen.locator("#board-sponsor").count() == 1
    first_shown_by_push(projector, "Acme Robotics", polls)  # the projector's edits came by push
    assert projector.evaluate("() => document.documentElement.scrollWidth") <= BIG_SCREEN["width"]
    assert phone.evaluate("() => document.documentElement.scrollWidth") <= PHONE["width"]
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    projector.screenshot(path=str(SCREENSHOTS / "edited-live-1920x1080.png"))
    phone.screenshot(path=str(SCREENSHOTS / "edited-live-390x844.png"), full_page=True)
    for page in (projector, phone):
        page.context.close()
