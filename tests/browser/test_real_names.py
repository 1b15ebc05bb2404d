"""Issue 31 on real screens (Chromium, 1920×1080 and 390×844): racers' real names in any script on the big screen,
race admin, statistics and the profile; sign-up with a real name on a phone; tracks and countries called by their
names. (The queue's numbering and the Next race form are in test_timekeeper_on_deck.py.) `browser_errors` (conftest)
fails any of these on a console error or CSP violation."""
from __future__ import annotations

import secrets
from pathlib import Path
from typing import Any

import pytest
import requests

from tests.browser.console_api import access_token, call, create_user, sign_in, submitted_race
from tests.browser.painted import painted

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "real-names"
BIG_SCREEN = {"width": 1920, "height": 1080}
PHONE = {"width": 390, "height": 844}
# (sign-in name, display name, country): the names the racers were refused with.
RACERS = (("bjorn", "Björn_Andersson", "SE"), ("zoe-m", "Zoë.Müller", "DE"), ("jose-g", "José-García", "ES"),
          ("amelie", "Amélie", "FR"), ("yamada", "山田太郎", "JP"), ("soren", "Søren", "DK"),
          ("lukasz", "Łukasz", "PL"), ("siobhan", "Siobhán", "IE"), ("minjun", "김민준", "KR"),
          ("noor", "نور", "EG"), ("emile", "Émile", "BE"))


def _admin_token(live_stack: Any) -> str:
    reply = requests.post(live_stack.url + "/api/auth/token", timeout=10, json={
        "username": live_stack.admin_username, "password": live_stack.admin_password})
    return str(reply.json()["access_token"])


NAMES_DAY = "2026-06-17"  # no other test's event is on this day: the statistics below filter on it


@pytest.fixture(scope="module")
def names_event(live_stack: Any) -> dict[str, Any]:
    """An event in Sweden with two named tracks; the eleven racers registered at the desk with their real names, each
    with a submitted race on the main stage, three on the side stage."""
    url, suffix = live_stack.url, secrets.token_hex(2)
    admin = _admin_token(live_stack)
    create_user(live_stack, f"names-op-{suffix}", "operator")
    token = access_token(live_stack, f"names-op-{suffix}")
    event = call(url, "POST", "/api/events", token=token, expect=201, body={
        "name": f"Names Cup {suffix}", "event_type": "OFFICIAL_TRACK_RACE", "date": NAMES_DAY,
        "country_code": "SE", "stats_visibility": "public",
        "tracks": [{"track_id": "1", "leaderboard_title": "Main stage"},
                   {"track_id": "2", "leaderboard_title": "Side stage"}]})
    racers = []
    for n, (username, name, country) in enumerate(RACERS):
        username = f"{username}-{suffix}"
        call(url, "POST", "/api/users", token=admin, expect=201, body={
            "username": username, "email": f"{username}@example.test", "country_code": country,
            "display_name": name})
        submitted_race(url, token, event["event_id"], username, [8_000 + 211 * n])
        if n < 3:
            submitted_race(url, token, event["event_id"], username, [9_000 + 97 * n], track_id="2")
        racers.append((username, name, country))
    return {"event_id": event["event_id"], "token": token, "racers": racers, "operator": f"names-op-{suffix}"}


def _shot(page: Any, name: str) -> None:
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    before = page.viewport_size
    for size in (BIG_SCREEN, PHONE):
        page.set_viewport_size(size)
        painted(page)  # the resized layout (and a board's paging) on screen before the screenshot
        page.screenshot(path=str(SCREENSHOTS / f"{name}-{size['width']}.png"))
    page.set_viewport_size(before)


def test_the_big_screen_shows_real_names_in_every_script(app_url, page, names_event):
    page.set_viewport_size(BIG_SCREEN)
    page.goto(f"{app_url}/leaderboard/{names_event['event_id']}?track=1&summary_seconds=0")
    # summary_seconds=0: no race summary holds the screen in place of the rows; live.js pages the rows.
    page.wait_for_function("() => [...document.querySelectorAll('.board-row')].some(row => !row.hidden"
                           " && row.getBoundingClientRect().height > 0)", timeout=60_000)
    shown = page.evaluate("() => [...document.querySelectorAll('.board-row .racer')].map(e => e.textContent.trim())")
    assert [name for _, name, _ in names_event["racers"]][:8] == shown[:8]
    assert page.get_by_test_id("board-subtitle").inner_text().startswith("Main stage")
    _shot(page, "big-screen")
    page.goto(f"{app_url}/leaderboard/{names_event['event_id']}?track=combined")
    assert page.get_by_test_id("board-subtitle").inner_text().startswith("All tracks")  # not "Track Combined"


def test_staff_pages_call_tracks_and_racers_by_their_names(app_url, page, names_event):
    sign_in(page, app_url, names_event["operator"])
    page.goto(f"{app_url}/console/races?event_id={names_event['event_id']}")
    rows = page.locator("[data-testid=races-table] tr", has_text="山田太郎")
    assert rows.count() == 1 and "Main stage" in rows.inner_text()
    side = page.locator("[data-testid=races-table] tr", has_text="Side stage")
    assert side.count() == 3
    # The changes to results (the lap edits that set these races' times) name racers the same way.
    assert "山田太郎" in page.get_by_test_id("audit-trail").inner_text()
    _shot(page, "race-admin")
    rows.get_by_role("link").first.click()
    page.get_by_test_id("race-track").wait_for()
    assert page.get_by_test_id("race-track").inner_text().startswith("Main stage")
    assert page.locator("h1").inner_text() == "Race of 山田太郎"
    page.goto(f"{app_url}/commentator/{names_event['event_id']}?track=1")
    nav = page.locator("nav a", has_text="Side stage")
    assert nav.count() == 1


def test_landing_and_statistics_name_countries_and_each_racers_own(app_url, page, names_event):
    page.goto(f"{app_url}/event/{names_event['event_id']}")
    assert "Sweden" in page.get_by_test_id("landing-when-where").inner_text()
    page.goto(f"{app_url}/stats?country=SE&from={NAMES_DAY}&to={NAMES_DAY}")  # this event's day alone
    fastest = page.get_by_test_id("stats-fastest")
    row = fastest.locator("tr", has_text="山田太郎")
    assert "Japan" in row.inner_text() and "Sweden" not in row.inner_text()
    assert "Sweden" in fastest.locator("tr", has_text="Björn_Andersson").inner_text()
    # One month of racing is drawn as bars, never as a one-point "line" (other tests of the session may add races in
    # other months to these Swedish statistics: then a line joins two points or more); at 1920 the page uses the
    # screen's width.
    lines = page.locator("[data-testid=stats-activity] polyline").evaluate_all(
        "lines => lines.map(line => line.points.numberOfItems)")
    assert all(points >= 2 for points in lines), f"a line drawn through a single point: {lines}"
    if not lines:  # one month: its races and events as bars
        assert page.locator("[data-testid=stats-activity] rect").count() >= 2
    page.set_viewport_size(BIG_SCREEN)
    assert page.locator("[data-testid=stats-page]").bounding_box()["width"] > 1200
    # Every axis label is drawn inside its chart (one was cut at the chart's edge at 1920).
    cut = page.locator("svg[data-testid=stats-activity]").evaluate("""svg => {
        const box = svg.getBoundingClientRect();
        return [...svg.querySelectorAll('text')].map(t => [t.textContent, t.getBoundingClientRect()])
            .filter(([, r]) => r.left < box.left - 1 || r.right > box.right + 1 || r.top < box.top - 1
                               || r.bottom > box.bottom + 1).map(([text]) => text);
    }""")
    assert cut == [], f"axis labels outside the chart: {cut}"
    _shot(page, "statistics")


def test_sign_up_on_a_phone_with_a_real_name(app_url, page):
    page.set_viewport_size(PHONE)
    page.goto(f"{app_url}/signup")
    suffix = secrets.token_hex(2)
    page.fill("#username", f"Zoe-{suffix}")
    page.fill("#display_name", "Zoë.Müller")
    page.fill("#email", f"zoe-{suffix}@example.test")
    page.fill("#country_code", "Germany")
    page.fill("#password", "Racer-Pass-2026")
    _shot(page, "sign-up")
    page.get_by_role("button", name="Sign up").click()
    page.get_by_test_id("confirmed").wait_for()  # a local stack confirms a sign-up at once
    # Signing in in another case is the same account.
    page.goto(f"{app_url}/login")
    page.fill("#username", f"zoe-{suffix}".upper())
    page.fill("#password", "Racer-Pass-2026")
    page.get_by_role("button", name="Sign in").click()
    page.wait_for_url(f"{app_url}/")
    page.goto(f"{app_url}/console/profile")
    assert page.get_by_test_id("profile-shown-name").inner_text() == "Zoë.Müller"
    _shot(page, "profile")

