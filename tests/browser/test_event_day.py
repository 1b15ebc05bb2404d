"""Issue 13 (event day) on real screens, in Chromium at 1920×1080 and 390×844: the big screen with 18 racers, the
chroma-key overlay, the track's title/footer/sponsor/links, and the console pages racers and staff meet."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.browser.console_api import PASSWORD, access_token, call, create_user, running_race, sign_in, submitted_race
from tests.browser.painted import painted

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "event-day"
BIG_SCREEN = {"width": 1920, "height": 1080}
PHONE = {"width": 390, "height": 844}
RACERS = 18
# Every text the big screen's page label ("2 / 3") shows, with the moment it showed it: [[text, Date.now()], ...].
RECORD_PAGE_LABELS = """
window.pageLabels = [];
new MutationObserver(() => {
  const label = document.querySelector('[data-board-page]');
  const text = label && !label.hidden ? label.textContent : '';
  const last = window.pageLabels[window.pageLabels.length - 1];
  if (text && (!last || last[0] !== text)) { window.pageLabels.push([text, Date.now()]); }
}).observe(document, {subtree: true, childList: true, characterData: true, attributes: true});
"""


@pytest.fixture(scope="module")
def event_day(live_stack: Any) -> dict[str, Any]:
    """An event whose track 1 board holds 18 racers, and a race running on it (the "Now racing" bar)."""
    url = live_stack.url
    create_user(live_stack, "day-op", "operator")
    token = access_token(live_stack, "day-op")
    fleet = call(url, "POST", "/api/fleets", token=token, body={"name": "Day fleet"}, expect=201)
    event = call(url, "POST", "/api/events", token=token, expect=201, body={
        "name": "Event Day Cup", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-06-01", "country_code": "SE",
        "sponsor": "Acme Robotics", "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"],
                                                "leaderboard_title": "Main stage",
                                                "leaderboard_footer": "Race again at the Acme booth"},
                                               {"track_id": "2", "leaderboard_title": "Side stage"}]})
    event_id = event["event_id"]
    racers = [f"day-racer-{n:02d}" for n in range(1, RACERS + 1)]
    for n, racer in enumerate(racers):
        call(url, "POST", "/api/users", token=admin_token(live_stack), expect=201,
             body={"username": racer, "email": f"{racer}@example.test", "country_code": "DE"})
        submitted_race(url, token, event_id, racer, [8_000 + 137 * n])
    # A racer who can sign in, with one submitted race of 8.838 s.
    create_user(live_stack, "day-mine", "racer")
    mine = submitted_race(url, token, event_id, "day-mine", [8_838, 9_101])
    create_user(live_stack, "day-live", "racer")
    running_race(url, token, event_id, "day-live")
    return {"event_id": event_id, "racers": racers + ["day-mine"], "token": token, "mine": mine}


_admin: dict[str, str] = {}


def admin_token(live_stack: Any) -> str:
    if "token" not in _admin:
        import requests

        _admin["token"] = requests.post(live_stack.url + "/api/auth/token", timeout=10, json={
            "username": live_stack.admin_username, "password": live_stack.admin_password}).json()["access_token"]
    return _admin["token"]


def shot(page: Any, name: str, *, sizes: tuple[dict[str, int], ...] = (BIG_SCREEN, PHONE)) -> None:
    """What a person sees, at the big screen's and a phone's size (test-artifacts/event-day/NAME-WIDTH.png)."""
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    before = page.viewport_size
    for size in sizes:
        page.set_viewport_size(size)
        painted(page)  # the resized layout (and a board's paging) on screen before the screenshot
        page.screenshot(path=str(SCREENSHOTS / f"{name}-{size['width']}.png"))
    page.set_viewport_size(before)


def visible_racers(page: Any) -> list[str]:
    """Racers whose whole row is on screen and not under the race bar."""
    return page.evaluate("""() => {
        const bar = document.querySelector('[data-testid=race-footer]');
        const limit = bar ? bar.getBoundingClientRect().top : window.innerHeight;
        return [...document.querySelectorAll('.board-row')].filter(row => {
            const box = row.getBoundingClientRect();
            return !row.hidden && box.height > 0 && box.top >= 0 && box.bottom <= Math.min(limit, window.innerHeight);
        }).map(row => row.dataset.racer);
    }""")


def test_every_one_of_18_racers_appears_on_the_big_screen_and_the_race_bar_covers_none(chromium, event_day,
                                                                                       app_url):
    context = chromium.new_context(viewport=BIG_SCREEN)
    page = context.new_page()
    page.goto(f"{app_url}/leaderboard/{event_day['event_id']}?track=1&page_seconds=2")
    page.get_by_test_id("race-footer").wait_for()
    seen: set[str] = set()
    pages_seen: set[str] = set()
    for _ in range(40):  # bounded: 2 s pages, polled every 250 ms
        seen.update(visible_racers(page))
        pages_seen.add(page.inner_text("[data-board-page]"))
        if seen >= set(event_day["racers"]) and len(pages_seen) > 1:
            break
        page.wait_for_timeout(250)
    assert seen == set(event_day["racers"]), f"never on screen: {sorted(set(event_day['racers']) - seen)} {pages_seen}"
    assert any("/" in label for label in pages_seen)  # "1 / 2": the audience sees there is more
    # The track's own title, its footer, the sponsor and the landing links (saved in the console) are shown.
    assert page.get_by_test_id("board-subtitle").inner_text().startswith("Main stage")
    assert page.get_by_test_id("board-footer").inner_text() == "Race again at the Acme booth"
    assert "Acme Robotics" in page.get_by_test_id("board-sponsor").inner_text()
    link = page.get_by_test_id("board-links").get_by_role("link").first
    assert link.get_attribute("href") == "/console/my-models"
    # Flags are images (flag-icons), not emoji that Windows and this Chromium show as letters or boxes.
    flag = page.locator(".board-row:not([hidden]) [data-testid=flag]").first
    assert flag.get_attribute("src") == "/static/vendor/flags/de.svg"
    assert flag.evaluate("img => img.complete && img.naturalWidth > 0")
    shot(page, "leaderboard-18-racers")
    context.close()


def test_the_default_landing_link_opens_for_a_racer(chromium, event_day, app_url, live_stack):
    create_user(live_stack, "day-landing", "racer")
    context = chromium.new_context(viewport=PHONE)
    page = context.new_page()
    sign_in(page, app_url, "day-landing")
    page.goto(f"{app_url}/leaderboard/{event_day['event_id']}")
    page.get_by_test_id("board-links").get_by_role("link").first.click()
    page.wait_for_url(f"{app_url}/console/my-models")
    assert page.locator("h1").first.inner_text().strip() != "Not allowed"
    context.close()


def test_chroma_overlay_panels_are_opaque_with_no_soft_shadow(chromium, event_day, app_url):
    context = chromium.new_context(viewport=BIG_SCREEN)
    page = context.new_page()
    page.goto(f"{app_url}/overlay/{event_day['event_id']}?trackId=1&chroma=1")
    page.get_by_test_id("lower-third").wait_for()
    styles = page.evaluate("""() => [...document.querySelectorAll('.lower-third, .standings, .overlay-title')]
        .map(el => { const s = getComputedStyle(el);
                     return {bg: s.backgroundColor, shadow: s.textShadow, box: s.boxShadow,
                             radius: s.borderRadius}; })""")
    assert styles
    for style in styles:
        assert style["bg"].startswith("rgb(") and not style["bg"].startswith("rgba("), style  # alpha 1
        assert style["shadow"] == "none" and style["box"] == "none" and style["radius"] in ("0px", ""), style
    shot(page, "overlay-chroma", sizes=(BIG_SCREEN,))
    context.close()


def test_the_events_table_fits_a_phone(chromium, event_day, app_url):
    context = chromium.new_context(viewport=PHONE)
    page = context.new_page()
    sign_in(page, app_url, "day-op")
    page.goto(app_url + "/console/events")
    table = page.get_by_test_id("events-table")
    assert table.bounding_box()["width"] <= PHONE["width"]
    assert page.evaluate("document.documentElement.scrollWidth") <= PHONE["width"]  # no sideways scrolling
    row = page.locator("tr", has_text="Event Day Cup")
    assert "Official track race" in row.inner_text() and "Fastest lap" in row.inner_text()  # labels, not enums
    shot(page, "events")
    context.close()


def board_colour(page: Any, racer: str) -> str:
    return page.evaluate("r => getComputedStyle(document.querySelector(`[data-racer='${r}']`))"
                         ".getPropertyValue('--racer-colour').trim().toLowerCase()", racer)


def test_a_racers_colour_change_reaches_the_board_and_the_default_is_preselected(chromium, event_day, app_url):
    context = chromium.new_context(viewport=PHONE)
    page = context.new_page()
    sign_in(page, app_url, "day-mine")
    page.goto(app_url + "/console/profile")
    assert page.get_by_label("#0000FF").is_checked()  # the colour the boards show before any save
    page.get_by_label("#FF0000").check()
    page.get_by_role("button", name="Save").click()
    page.get_by_test_id("notice").wait_for()
    board = context.new_page()
    board.goto(f"{app_url}/leaderboard/{event_day['event_id']}?track=1")
    assert board_colour(board, "day-mine") == "#ff0000"
    context.close()


def test_my_races_names_the_event_and_writes_lap_times_like_every_other_page(chromium, event_day, app_url):
    context = chromium.new_context(viewport=PHONE)
    page = context.new_page()
    sign_in(page, app_url, "day-mine")
    page.goto(app_url + "/console/my-races")
    row = page.get_by_test_id("race-row").first
    text = row.inner_text()
    assert "Event Day Cup" in text and event_day["event_id"] not in text
    assert "Main stage" in text and "Track 1" not in text  # issue 31: the track by its name, not its number
    assert "0:08.838" in text and "Submitted" in text
    assert page.evaluate("document.documentElement.scrollWidth") <= PHONE["width"]  # nothing cut off on a phone
    row.get_by_role("button", name="Show laps").click()
    assert "0:08.838" in page.get_by_test_id("race-laps").inner_text()
    shot(page, "my-races")
    context.close()


def test_the_race_editor_lines_its_inputs_up_under_their_headings(chromium, event_day, app_url):
    context = chromium.new_context(viewport=BIG_SCREEN)
    page = context.new_page()
    sign_in(page, app_url, "day-op")
    page.goto(f"{app_url}/console/races/{event_day['event_id']}/{event_day['mine']}")
    editor = page.get_by_test_id("lap-editor")
    headings = editor.locator("thead th")
    first_row = editor.get_by_test_id("lap-row").first
    for column, field in ((1, "input[name=time_s]"), (2, "input[name=resets]"), (3, "input[name=is_valid]")):
        heading = headings.nth(column).bounding_box()
        box = first_row.locator(field).bounding_box()
        assert heading["x"] - 1 <= box["x"] < heading["x"] + heading["width"], (column, heading, box)
    # Saving from the aligned row still edits the lap.
    first_row.locator("input[name=time_s]").fill("8.9")
    first_row.get_by_role("button", name="Save lap 1").click()
    page.wait_for_load_state()
    assert page.get_by_test_id("lap-row").first.locator("input[name=time_s]").input_value() == "8.900"
    shot(page, "race-edit")
    context.close()


def test_the_cars_page_confirms_an_emergency_stop_and_refreshes_itself(chromium, event_day, app_url):
    url, token = app_url, event_day["token"]
    fleet = call(url, "POST", "/api/fleets", token=token, body={"name": "Cars page fleet"}, expect=201)
    code = call(url, "POST", "/api/devices/activation-codes", token=token, expect=201, body={
        "fleet_id": fleet["fleet_id"], "hostname": "estop-car", "device_kind": "car"})["code"]
    credential = call(url, "POST", "/api/devices/activate", expect=201,
                      body={"code": code, "hostname": "estop-car", "device_kind": "car"})["credential"]
    call(url, "POST", "/api/devices/self/heartbeat", device=credential, body={"battery_pct": 77})

    context = chromium.new_context(viewport=BIG_SCREEN)
    page = context.new_page()
    sign_in(page, url, "day-op")
    page.goto(url + "/console/cars")
    row = page.locator("tr[data-hostname='estop-car']")
    assert row.get_by_test_id("loaded-model").inner_text() == "—"
    # The fleet picker shows the whole fleet name: its box is at least as wide as the name's text.
    fits = page.evaluate("""() => {
        const select = document.querySelector("tr[data-hostname='estop-car'] select[name=fleet_id]");
        const context = document.createElement('canvas').getContext('2d');
        context.font = getComputedStyle(select).font;
        return select.getBoundingClientRect().width
            >= context.measureText(select.selectedOptions[0].text).width + 16;
    }""")
    assert fits, "the fleet name is cut in its picker"
    row.get_by_role("button", name="Emergency stop").click()
    page.wait_for_load_state()
    assert "Emergency stop sent to estop-car" in page.get_by_test_id("notice").inner_text()
    live = page.locator("tr[data-hostname='estop-car']").get_by_test_id("car-live")
    assert "Emergency stop: sent, waiting for the car" in live.inner_text()

    # The car does it and says so, and reports its loaded model: the open page shows both without a reload.
    pending = call(url, "GET", "/api/devices/self/commands", device=credential)["commands"]
    stop = next(c for c in pending if c["type"] == "EMERGENCY_STOP")
    call(url, "POST", f"/api/devices/self/commands/{stop['command_id']}/ack", device=credential,
         body={"result": "ok"})
    call(url, "POST", "/api/devices/self/heartbeat", device=credential,
         body={"battery_pct": 64, "model": {"name": "fast-model", "md5": "0" * 32},
               "faults": ["stopped: emergency stop"]})
    page.wait_for_function("""() => {
        const cell = document.querySelector("tr[data-hostname='estop-car'] [data-testid=car-live]");
        return cell && cell.innerText.includes('Emergency stop: done by the car') && cell.innerText.includes('64 %');
    }""", timeout=15_000)
    assert live.get_by_test_id("loaded-model").inner_text() == "fast-model"
    assert "stopped: emergency stop" in live.get_by_test_id("car-fault").inner_text()
    shot(page, "cars")
    context.close()


def test_every_track_has_its_links_and_the_overlay_link_builder_explains_its_options(chromium, event_day, app_url):
    context = chromium.new_context(viewport=BIG_SCREEN)
    page = context.new_page()
    sign_in(page, app_url, "day-op")
    nav = page.get_by_test_id("nav-links").inner_text()
    assert "League" in nav and "Model registry" not in nav  # one name per registry, the league in the bar
    page.goto(app_url + "/console/events")
    # This event's row: other tests' events on the shared stack have a track 2 too.
    side = page.locator(f'tr[data-event-id="{event_day["event_id"]}"]').get_by_test_id("track-links-2")
    assert side.get_by_role("link", name="Timekeeper").get_attribute("href").endswith(f"{event_day['event_id']}/2")
    side.get_by_role("link", name="Overlay").click()
    page.get_by_label("Chroma key background").check()
    page.get_by_label("Gap to the leader").uncheck()
    page.get_by_role("button", name="Update the link").click()
    link = page.get_by_test_id("overlay-link").inner_text()
    assert link == (f"{app_url}/overlay/{event_day['event_id']}?trackId=2&chroma=true&chromaColor=%2300FF00"
                    "&gapToLeader=false")
    assert "OBS" in page.locator("section").inner_text()  # the options are explained where they are chosen
    preview = context.new_page()
    preview.goto(link)
    assert preview.evaluate("getComputedStyle(document.body).backgroundColor") == "rgb(0, 255, 0)"
    shot(page, "overlay-link")
    context.close()


def test_a_name_with_a_dash_is_accepted_at_the_desk_and_at_self_sign_up(chromium, app_url, live_stack):
    """One username rule: the desk took "kim-b" while self sign-up refused "kim-c" (issue 13, item 5)."""
    create_user(live_stack, "day-desk", "registration")
    context = chromium.new_context(viewport=PHONE)
    desk = context.new_page()
    sign_in(desk, app_url, "day-desk")
    desk.goto(app_url + "/console/registration")
    desk.fill("#username", "kim-b")
    desk.fill("#email", "kim-b@example.test")
    desk.fill("#country_code", "Sweden (SE)")
    desk.get_by_role("button", name="Create racer").click()
    assert desk.get_by_test_id("registered-username").inner_text() == "kim-b"
    racer = context.browser.new_context(viewport=PHONE).new_page()
    racer.goto(app_url + "/signup")
    racer.fill("#username", "kim-c")
    racer.fill("#email", "kim-c@example.test")
    racer.fill("#country_code", "sweden")
    racer.fill("#password", PASSWORD)
    racer.get_by_role("button", name="Sign up").click()
    # A local stack confirms self sign-ups itself (no email can arrive offline): the racer may sign in at once.
    confirmed = racer.get_by_test_id("confirmed")
    confirmed.wait_for()
    assert "kim-c" in confirmed.inner_text() and "is confirmed" in confirmed.inner_text()
    racer.context.close()
    context.close()


def test_a_new_result_on_a_later_page_is_shown_at_once_and_held_for_a_whole_page(chromium, event_day, app_url,
                                                                                  live_stack):
    """Big-screen paging dwells on a new entry: a result that lands on page 2 while page 1 is up is shown straight
    away, highlighted, and held for at least a page time before the board pages on. Runs last in this file: it
    changes a result (staff correct day-mine's laps to the slowest of the day: the row moves to the last page)."""
    context = chromium.new_context(viewport=BIG_SCREEN)
    page = context.new_page()
    page.add_init_script(RECORD_PAGE_LABELS)
    page.goto(f"{app_url}/leaderboard/{event_day['event_id']}?track=1&page_seconds=8&summary_seconds=0")
    label = "document.querySelector('[data-board-page]')"
    # Page 1 comes up as the board opens, and by itself the board stays on it for 8 s: when it came up is read from
    # the page's own record of its page label, not from when this test first saw it.
    page.wait_for_function(f"() => {label} && !{label}.hidden && /^1 \\/ [2-9]/.test({label}.textContent)",
                           timeout=20_000)
    page_one_at = page.evaluate("() => window.pageLabels.find(([text]) => text.startsWith('1 /'))[1]")
    path = f"/api/events/{event_day['event_id']}/races/{event_day['mine']}"
    for lap, time_ms in ((0, 19_999), (1, 19_998)):
        call(live_stack.url, "PUT", f"{path}/laps/{lap}", token=event_day["token"],
             body={"time_ms": time_ms, "is_valid": True})
    moved = page.locator('.board-row[data-racer="day-mine"]').filter(has_text="0:19.998")
    moved.wait_for(state="visible")
    shown_at = page.evaluate("() => Date.now()")
    # The board jumped to the new result's page long before page 1's 8 s were up, and highlights it.
    assert shown_at - page_one_at < 6_000, f"page 2 came only after {shown_at - page_one_at} ms: paging, not a jump"
    assert "is-new" in (moved.get_attribute("class") or "")
    assert "day-mine" in visible_racers(page)
    # Held for at least a whole page time, then the board pages on to page 1 again.
    page.wait_for_function(f"() => {label}.textContent.startsWith('1 /')", timeout=30_000)
    held_ms = page.evaluate("() => Date.now()") - shown_at
    assert held_ms >= 7_500, f"the new result's page gave way after {held_ms} ms"
    context.close()
