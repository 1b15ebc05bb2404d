"""Issue 31: an edit of the event's name or logo reached an open stream overlay (an OBS browser source nobody reloads
during a stream) only after a reload. Here the overlay is open (pushed by the live server, and a second one polling
the app because its stream is refused) while staff rename the event and upload its logo: both overlays show them
without a reload, and the race on the overlay stays."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.browser.screen_edits import edit_event, first_shown_by_push, pushed_and_polled, raced_event
from tests.browser.test_event_logo import BIG_SCREEN
from tests.browser.test_live_push import wait_until

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "overlay"


def test_a_renamed_event_and_a_new_logo_reach_an_open_overlay(chromium: Any, live_stack: Any, app_url: str,
                                                              browser_errors: Any, tmp_path: Path) -> None:
    event_id = raced_event(live_stack, app_url, "overlay-op", "overlay-racer", "Overlay Cup", {"track_id": "1"})
    streamed, polls, polled = pushed_and_polled(chromium, f"{app_url}/overlay/{event_id}?track=1", "overlay",
                                                browser_errors, BIG_SCREEN)
    for overlay in (streamed, polled):
        assert overlay.get_by_test_id("overlay-title").inner_text() == "Overlay Cup"
        assert overlay.get_by_test_id("overlay-logo").count() == 0
        assert "overlay-racer" in overlay.locator("#overlay-live").inner_text()

    edit_event(chromium, app_url, "overlay-op", event_id, {"#name": "Overlay Cup Finals"}, tmp_path)

    for overlay in (streamed, polled):  # no reload: the live region brings the edits
        overlay.wait_for_selector("[data-testid=overlay-title]:text-is('Overlay Cup Finals')", timeout=20_000)
        overlay.wait_for_selector("[data-testid=overlay-logo]", timeout=20_000)
        wait_until(overlay, "() => document.querySelector('[data-testid=overlay-logo]').complete")
        assert overlay.locator("#overlay-title").count() == 1 and overlay.locator("#overlay-logo-slot").count() == 1
        assert overlay.locator("#overlay-live").count() == 1  # the race region stays, with the racer
        assert "overlay-racer" in overlay.locator("#overlay-live").inner_text()
    first_shown_by_push(streamed, "Overlay Cup Finals", polls)  # the streamed overlay's edits came by push
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    streamed.screenshot(path=str(SCREENSHOTS / "edited-live-1920x1080.png"))
    for page in (streamed, polled):
        page.context.close()
