"""What the tests of live edits share (big screen and stream overlay): an event with one raced racer, one page on the
live server's push and one forced to poll the app (its stream refused), and staff editing the event in the console."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from tests.browser.console_api import access_token, call, create_user, sign_in, submitted_race
from tests.browser.test_event_logo import BIG_SCREEN, sponsor_logo
from tests.browser.test_live_push import wait_until


def raced_event(live_stack: Any, app_url: str, staff: str, racer: str, name: str, track: dict[str, str]) -> str:
    """A new event (one track) with a race of `racer`, made by operator `staff`; its id."""
    create_user(live_stack, staff, "operator")
    create_user(live_stack, racer, "racer")
    token = access_token(live_stack, staff)
    event_id = call(app_url, "POST", "/api/events", token=token, expect=201, body={
        "name": name, "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-06-02", "country_code": "SE",
        "tracks": [track]})["event_id"]
    submitted_race(app_url, token, event_id, racer, [9_120])
    return str(event_id)


# Each swap of a live region: whether the stream pushed it (live.js passes dremPushedAt with a pushed fragment) or a
# poll brought it, and what the page then showed.
RECORD_SWAPS = """window.dremSwaps = [];
document.addEventListener("htmx:afterSwap", function (event) {
  window.dremSwaps.push({pushed: !!event.detail && "dremPushedAt" in event.detail, text: document.body.innerText});
});"""


def first_shown_by_push(page: Any, text: str, polls: list[str]) -> None:
    """The first swap that showed `text` on `page` came by push. A poll or two of a loaded machine's stream reconnect
    is no failure (the stream is what is tested, and what it brought first)."""
    swaps = page.evaluate("() => window.dremSwaps")
    first = next((swap for swap in swaps if text in swap["text"]), None)
    assert first is not None and first["pushed"], (
        f"{text!r} first came by {'no swap' if first is None else 'poll'}; swaps pushed: "
        f"{[swap['pushed'] for swap in swaps]}, polls: {polls}")


def pushed_and_polled(chromium: Any, url: str, kind: str, browser_errors: Any,
                      polled_viewport: dict[str, int]) -> tuple[Any, list[str], Any]:
    """`url` open twice: on the live server's stream (with the app polls it makes, which should be none), and with its
    stream refused (503) so it polls the app instead."""
    pushed = chromium.new_context(viewport=BIG_SCREEN).new_page()
    pushed.add_init_script(RECORD_SWAPS)
    polls: list[str] = []
    pushed.on("request", lambda request: polls.append(request.url) if "/live?" in request.url else None)
    pushed.goto(url)
    wait_until(pushed, "() => !!window.dremLiveStream && window.dremLiveStream.readyState === 1")
    polled = chromium.new_context(viewport=polled_viewport).new_page()
    browser_errors.allow(rf"/live/{kind}/.*status of 503")  # the second page's stream, refused on purpose
    polled.route(re.compile(rf".*/live/{kind}/.*"), lambda route: route.fulfill(status=503, body="full"))
    polled.goto(url)
    return pushed, polls, polled


def edit_event(chromium: Any, app_url: str, staff: str, event_id: str, fields: dict[str, str], logo_dir: Path) -> None:
    """Staff fill the event's edit form with `fields` ({selector: text}), save it, then upload a logo."""
    page = chromium.new_context(viewport=BIG_SCREEN).new_page()
    sign_in(page, app_url, staff)
    page.goto(f"{app_url}/console/events/{event_id}/edit")
    for selector, text in fields.items():
        page.fill(selector, text)
    page.get_by_role("button", name="Save event").click()
    page.wait_for_url(re.compile(r".*/console/events\?.*"))
    page.goto(f"{app_url}/console/events/{event_id}/edit")
    page.set_input_files("#logo-file", str(sponsor_logo(logo_dir / "acme.png")))
    page.get_by_role("button", name="Upload logo").click()
    page.get_by_test_id("notice").wait_for()
    page.context.close()
