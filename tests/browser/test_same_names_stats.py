"""Issue 31: two racers both called Björn on the statistics page, at 1920×1080 and 390×844. The fastest-lap tables
(overall and per track type) name each with their sign-in name after it, 山田 as she writes it, and the page fits a
phone. `browser_errors` (conftest) fails it on a console error or CSP violation."""
from __future__ import annotations

import secrets
from pathlib import Path
from typing import Any

import pytest

from tests.browser.console_api import access_token, call, create_user, submitted_race
from tests.browser.test_real_names import _admin_token

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "same-names"
SAME_NAMES_DAY = "2026-06-19"  # no other test's event is on this day: the page below filters on it


def test_two_racers_called_bjorn_are_told_apart_on_the_statistics_page(chromium: Any, live_stack: Any, app_url: str,
                                                                        browser_errors: Any) -> None:
    suffix = secrets.token_hex(2)
    admin = _admin_token(live_stack)
    create_user(live_stack, f"stats-op-{suffix}", "operator")
    token = access_token(live_stack, f"stats-op-{suffix}")
    event_id = call(app_url, "POST", "/api/events", token=token, expect=201, body={
        "name": "Björn Cup", "event_type": "OFFICIAL_TRACK_RACE", "date": SAME_NAMES_DAY, "country_code": "SE",
        "stats_visibility": "public", "tracks": [{"track_id": "1", "leaderboard_title": "Main stage"}]})["event_id"]
    expected = []
    for username, name, country, lap_ms in (("bjorn_a", "Björn", "SE", 8_700), ("yamada", "山田", "JP", 9_100),
                                            ("bjorn_b", "björn", "NO", 9_400)):
        username = f"{username}_{suffix}"
        call(app_url, "POST", "/api/users", token=admin, expect=201, body={
            "username": username, "email": f"{username}@example.test", "country_code": country,
            "display_name": name})
        submitted_race(app_url, token, event_id, username, [lap_ms])
        expected.append(f"{name} ({username})" if name.casefold() == "björn" else name)

    for size in ({"width": 1920, "height": 1080}, {"width": 390, "height": 844}):
        page = chromium.new_context(viewport=size).new_page()
        page.goto(f"{app_url}/stats?from={SAME_NAMES_DAY}&to={SAME_NAMES_DAY}")
        tables = page.locator("table[data-testid^=stats-fastest]")
        assert tables.count() >= 2  # overall and per track type
        for table in tables.all():
            names = [cell.strip() for cell in table.locator("tbody tr td:nth-child(2)").all_inner_texts()]
            assert names == expected, names
        assert page.evaluate("() => document.documentElement.scrollWidth") <= size["width"]
        SCREENSHOTS.mkdir(parents=True, exist_ok=True)
        page.get_by_test_id("stats-fastest").scroll_into_view_if_needed()
        page.screenshot(path=str(SCREENSHOTS / f"stats-same-names-{size['width']}x{size['height']}.png"))
        page.context.close()
