"""Journey 4: an operator runs a whole race from the timekeeper screen with the keyboard (start, laps, a reset, a
DNF, an undo of a false finish, end), submits it, and finds it in race admin and in the CSV download."""
from __future__ import annotations

import csv
import io
from pathlib import Path

import pytest

from tests.browser.console_api import access_token, call, create_user, sign_in

pytestmark = pytest.mark.browser

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"


def _laps(page) -> int:
    return page.locator("[data-testid=laps] tr[data-lap]").count()


def _wait_laps(page, count: int) -> None:
    page.wait_for_function(f"() => document.querySelectorAll('[data-testid=laps] tr[data-lap]').length === {count}")


def test_operator_runs_a_race_with_keyboard_shortcuts_and_finds_it_in_race_admin(live_stack, app_url, page):
    create_user(live_stack, "keys-op", "operator")
    create_user(live_stack, "keys-racer", "racer")
    token = access_token(live_stack, "keys-op")
    fleet = call(app_url, "POST", "/api/fleets", token=token, body={"name": "Keyboard fleet"}, expect=201)
    event = call(app_url, "POST", "/api/events", token=token, expect=201, body={
        "name": "Keyboard Cup", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-07-01", "country_code": "GB",
        "race_config": {"race_time_min": 3, "resets_per_lap": 0},
        "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"], "leaderboard_title": "Keyboard track"}]})
    event_id = event["event_id"]

    sign_in(page, app_url, "keys-op")
    page.goto(f"{app_url}/console/timekeeper/{event_id}/1")
    assert "No timer in this track's fleet" in page.get_by_test_id("timer-status").inner_text()
    page.fill("#racer_username", "keys-racer")
    page.get_by_role("button", name="Ready race").click()
    status = page.get_by_test_id("race-status")
    status.wait_for()
    assert status.inner_text() == "Ready to start"
    assert page.get_by_test_id("time-left").inner_text() == "3:00.000"

    page.keyboard.press("Space")  # start
    page.wait_for_function("() => document.querySelector('[data-testid=race-status]').textContent === 'Running'")
    # ticking down between polls (a condition, not a pause: a loaded machine paints late, never wrong)
    page.wait_for_function("() => document.querySelector('[data-testid=time-left]').textContent < '2:59.000'",
                           timeout=30_000)

    page.keyboard.press("l")  # lap 1, clean
    _wait_laps(page, 1)
    page.keyboard.press("r")  # a reset on lap 2 ...
    page.wait_for_function("() => document.querySelector('[data-testid=resets]').textContent.trim() === '1 / 0'")
    page.keyboard.press("r")
    page.wait_for_function("() => document.querySelector('[data-testid=resets]').textContent.trim() === '2 / 0'")
    page.keyboard.press("Shift+R")  # ... one taken back
    page.wait_for_function("() => document.querySelector('[data-testid=resets]').textContent.trim() === '1 / 0'")
    # the take-back's answer is swapped in and settled (htmx drops its request class) before the next key
    page.wait_for_function("() => !document.querySelector('.htmx-request, .htmx-settling, .htmx-swapping')")
    page.keyboard.press("Enter")  # lap 2: one reset, over the limit of 0 → invalid
    _wait_laps(page, 2)
    page.keyboard.press("l")  # a false finish (lap 3) ...
    _wait_laps(page, 3)
    page.keyboard.press("u")  # ... undone
    _wait_laps(page, 2)
    page.keyboard.press("d")  # DNF: an invalid lap 3, and the race pauses
    _wait_laps(page, 3)
    page.wait_for_function("() => document.querySelector('[data-testid=race-status]').textContent === 'Paused'")
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "timekeeper.png"), full_page=True)

    laps = page.get_by_test_id("laps")
    assert "✔ valid" in laps.locator("tr[data-lap='1']").inner_text()
    assert "✘ invalid" in laps.locator("tr[data-lap='2']").inner_text()
    assert "DNF" in laps.locator("tr[data-lap='3']").inner_text()

    # A second screen (another tablet) shows the same race.
    other = page.context.new_page()
    other.goto(f"{app_url}/console/timekeeper/{event_id}/1")
    assert other.get_by_test_id("racer").inner_text() == "keys-racer"
    assert other.locator("[data-testid=laps] tr[data-lap]").count() == 3
    other.close()

    # "e" ends the race only after a confirmation (a stray key must not): dismissed first, then accepted.
    asked: list[str] = []
    page.once("dialog", lambda dialog: (asked.append(dialog.message), dialog.dismiss()))
    page.keyboard.press("e")
    assert asked == ["End this race now? The clock stops for good."]
    assert page.get_by_role("button", name="End race").is_visible()  # not ended: still the live race's buttons
    page.once("dialog", lambda dialog: dialog.accept())
    page.keyboard.press("e")  # end
    page.get_by_role("button", name="Submit race").click()
    page.get_by_role("button", name="Ready race").wait_for()  # back to the next racer

    page.goto(f"{app_url}/console/races?event_id={event_id}")
    row = page.locator("[data-testid=races-table] tr", has_text="keys-racer")
    assert "Submitted" in row.inner_text() and "3 (1)" in row.inner_text()

    download = page.request.get(app_url + page.get_by_test_id("csv-laps").get_attribute("href"))
    assert download.ok and download.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(download.text())))
    assert [(r["Username"], r["Lap #"], r["Resets"], r["Valid"]) for r in rows] == [
        ("keys-racer", "1", "0", "true"), ("keys-racer", "2", "1", "false"), ("keys-racer", "3", "0", "false")]


def test_timekeeper_types_picks_a_suggested_racer_and_readies_the_race(live_stack, app_url, page, browser_errors):
    """The suggestions under the site's CSP (`script-src 'self'`, no eval): typing the start of a name lists the
    racers, shown by the name they go by; picking one and "Ready race" readies that racer. `browser_errors` fails
    this on any CSP violation or console error while typing, not only on page load."""
    create_user(live_stack, "pick-op", "operator")
    create_user(live_stack, "pick-admin", "admin")
    admin, token = access_token(live_stack, "pick-admin"), access_token(live_stack, "pick-op")
    for username, name in (("mk-longname", "Mary-Kate Longname"), ("mk-other", "Zoë.Müller"), ("yamada-t", "山田太郎")):
        call(app_url, "POST", "/api/users", token=admin, expect=201, body={
            "username": username, "email": f"{username}@example.test", "country_code": "JP", "display_name": name})
    fleet = call(app_url, "POST", "/api/fleets", token=token, body={"name": "Pick fleet"}, expect=201)
    event = call(app_url, "POST", "/api/events", token=token, expect=201, body={
        "name": "Pick Cup", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-07-01", "country_code": "JP",
        "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"]}]})

    sign_in(page, app_url, "pick-op")
    page.goto(f"{app_url}/console/timekeeper/{event['event_id']}/1")
    field = page.locator("#racer_username")
    field.click()
    page.keyboard.type("mk-")
    suggestions = page.locator("#racers-list option")
    page.wait_for_function("() => document.querySelectorAll('#racers-list option').length === 2")
    assert [suggestions.nth(i).get_attribute("value") for i in range(2)] == ["mk-longname", "mk-other"]
    assert suggestions.nth(1).get_attribute("label") == "Zoë.Müller (mk-other)"
    # Picking a suggestion puts its value in the field (what choosing from the datalist does).
    field.fill(suggestions.nth(1).get_attribute("value"))
    page.get_by_role("button", name="Ready race").click()
    page.get_by_test_id("race-status").wait_for()
    assert page.get_by_test_id("race-status").inner_text() == "Ready to start"
    assert page.get_by_test_id("racer").inner_text() == "Zoë.Müller"
    assert browser_errors.seen == []
