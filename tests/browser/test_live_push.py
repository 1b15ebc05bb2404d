"""The public pages with the live server, in real Chromium: the live region subscribes to drem_live's event stream
(gzip, decoded by the browser), is updated by push without polling the app, falls back to polling when the stream is
refused, and never swaps in a fragment older than the one it shows (the rule the server orders tokens by)."""
from __future__ import annotations

import re
import time
from typing import Any

import pytest

from chalicelib.views.live_regions import token_is_newer
from tests.browser.test_live_pages import start_race, strip

pytestmark = pytest.mark.browser


def wait_until(page: Any, predicate: str, timeout_s: float = 10.0) -> None:
    """Poll `predicate` (a JS arrow function) from outside: the pages' CSP forbids wait_for_function's eval."""
    deadline = time.monotonic() + timeout_s
    while not page.evaluate(predicate):
        assert time.monotonic() < deadline, f"never true: {predicate}"
        page.wait_for_timeout(50)


def test_the_board_and_overlay_are_pushed_gzipped_without_polling_the_app(live_stack: Any, page: Any) -> None:
    eid, _rid, timer = start_race(live_stack.url, live_stack.admin_username, live_stack.admin_password,
                                  racer="push-lina")
    polls: list[str] = []
    streams: list[dict[str, str]] = []
    page.on("request", lambda request: polls.append(request.url) if "/live?" in request.url else None)
    page.on("response", lambda response: streams.append(response.all_headers())
            if "/live/leaderboard/" in response.url else None)
    page.goto(f"{live_stack.url}/leaderboard/{eid}?lang=en")
    wait_until(page, "() => !!window.dremLiveStream && window.dremLiveStream.readyState === 1")
    overlay = page.context.new_page()
    overlay.goto(f"{live_stack.url}/overlay/{eid}?track=1")
    wait_until(overlay, "() => !!window.dremLiveStream && window.dremLiveStream.readyState === 1")
    first = overlay.get_by_test_id("time-left").inner_text()  # the race clock ticks locally between pushes
    wait_until(overlay, f"() => document.querySelector('[data-testid=time-left]').textContent !== {first!r}")

    seed = int(time.time() * 1000)
    strip(live_stack.url, timer, eid, seed, "push-1")
    strip(live_stack.url, timer, eid, seed + 9_876, "push-2")
    page.wait_for_selector('#board-live .board-row[data-racer="push-lina"] .time:has-text("0:09.876")')
    overlay.wait_for_selector('[data-testid="previous-lap"]:has-text("0:09.876")')
    assert streams and streams[0].get("content-encoding") == "gzip", streams  # the browser decoded gzip SSE
    assert polls == [], polls  # while the stream is up the htmx polls are held back


def _with_version(html: str, token: str, marker: str) -> str:
    html = re.sub(r'data-version="[^"]*"', f'data-version="{token}"', html, count=1)
    return html.replace("</section>", f'<p data-testid="marker">{marker}</p></section>', 1)


def test_a_poll_answer_older_than_the_shown_board_is_refused(live_stack: Any, page: Any, browser_errors: Any) -> None:
    eid, _rid, _timer = start_race(live_stack.url, live_stack.admin_username, live_stack.admin_password,
                                   racer="stale-omar")
    browser_errors.allow(r"/live/leaderboard/.*status of 503")  # the refused stream this test makes on purpose
    page.route(re.compile(r".*/live/leaderboard/.*"), lambda route: route.fulfill(status=503, body="full"))
    page.goto(f"{live_stack.url}/leaderboard/{eid}?lang=en")
    region = page.locator("#board-live")
    shown = region.get_attribute("data-version")
    groups = shown.split(".")
    older = ".".join([str(int(groups[0]) - 1), *groups[1:]])
    newer = ".".join([str(int(groups[0]) + 1000), *groups[1:]])
    html = region.evaluate("el => el.outerHTML")
    answered: list[str] = []

    def answer(route: Any, token: str, marker: str) -> None:
        answered.append(token)
        route.fulfill(status=200, content_type="text/html", body=_with_version(html, token, marker))

    # On AWS another Lambda instance may still have the older board cached: the page must keep what it shows.
    page.route(re.compile(r".*/leaderboard/[^/]+/live\?.*"), lambda route: answer(route, older, "STALE"))
    deadline = time.monotonic() + 10
    while len(answered) < 3 and time.monotonic() < deadline:
        page.wait_for_timeout(100)  # the polls run every 500 ms; wait until three stale answers came back
    assert len(answered) >= 3, "the page did not fall back to polling when the stream was refused"
    assert region.get_attribute("data-version") == shown and page.get_by_test_id("marker").count() == 0

    page.unroute(re.compile(r".*/leaderboard/[^/]+/live\?.*"))
    page.route(re.compile(r".*/leaderboard/[^/]+/live\?.*"), lambda route: answer(route, newer, "FRESH"))
    page.get_by_test_id("marker").filter(has_text="FRESH").wait_for()
    assert page.locator("#board-live").get_attribute("data-version") == newer


TOKEN_CASES = [("2.5-0", "1.5-0"), ("1.6-0", "1.5-2"), ("1.5-0", "1.5-1"), ("1.5-0", "2.5-0"), ("1.5-0", "1.5-0"),
               ("2.4-0", "1.5-0"), ("3.7-1.7-0", "3.7-0.7-0"), ("3.7-1", ""), ("x", "y"), ("1.5", "1.5-0")]


def test_the_page_orders_tokens_like_the_server(live_stack: Any, page: Any) -> None:
    page.set_content(f'<script src="{live_stack.url}/static/live.js"></script>')
    wait_until(page, "() => typeof window.dremTokenIsNewer === 'function'")
    in_browser = page.evaluate("cases => cases.map(([a, b]) => window.dremTokenIsNewer(a, b))", TOKEN_CASES)
    assert in_browser == [token_is_newer(a, b or None) for a, b in TOKEN_CASES]
