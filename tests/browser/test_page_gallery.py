"""Every main page as people see it, at the big screen's (1920×1080), a tablet's (768×1024) and a phone's (390×844)
size: each answers, nothing spills sideways out of the screen, the browser reports no error (no answer >= 400, no
missing favicon, no script error), and a screenshot of each lands in test-artifacts/gallery/NAME-WIDTHxHEIGHT.png
(the ones in docs/screenshots/ are copied from there after being looked at)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import requests

from tests.browser.console_api import PASSWORD, access_token, call, create_user, running_race, submitted_race

pytestmark = pytest.mark.browser

GALLERY = Path(__file__).resolve().parents[2] / "test-artifacts" / "gallery"
BIG_SCREEN = {"width": 1920, "height": 1080}
TABLET = {"width": 768, "height": 1024}
PHONE = {"width": 390, "height": 844}
SIZES = (BIG_SCREEN, TABLET, PHONE)


@pytest.fixture(scope="module")
def gallery_event(live_stack: Any) -> dict[str, str]:
    """An event with a fleet, five racers with a submitted race each and one race running on track 1."""
    url = live_stack.url
    create_user(live_stack, "gallery-op", "operator")
    token = access_token(live_stack, "gallery-op")
    fleet = call(url, "POST", "/api/fleets", token=token, expect=201,  # a long name must wrap on a phone
                 body={"name": "Gallery fleet of the main hall (Björn, Zoë and 山田 race here)"})
    event = call(url, "POST", "/api/events", token=token, expect=201, body={
        "name": "Gallery Grand Prix", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-06-01", "country_code": "FR",
        "sponsor": "Acme Robotics", "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"],
                                                "leaderboard_title": "Main stage"}]})
    event_id = event["event_id"]
    race_id = ""
    for n, (racer, country) in enumerate([("gallery-ana", "ES"), ("gallery-bo", "SE"), ("gallery-chi", "JP"),
                                          ("gallery-dee", "DE"), ("gallery-eli", "FR")]):
        create_user(live_stack, racer, "racer")
        call(url, "PUT", "/api/me/profile", token=access_token(live_stack, racer), expect=(200, 201),
             body={"country_code": country})
        race_id = submitted_race(url, token, event_id, racer, [9_120 + 211 * n, 9_480 + 157 * n])
    create_user(live_stack, "gallery-live", "racer")
    running_race(url, token, event_id, "gallery-live")
    return {"event_id": event_id, "race_id": race_id}


def public_pages(event: dict[str, str]) -> dict[str, str]:
    event_id = event["event_id"]
    return {"login": "/login", "signup": "/signup", "event-landing": f"/event/{event_id}",
            "leaderboard": f"/leaderboard/{event_id}?track=1",
            "overlay-chroma": f"/overlay/{event_id}?track=1&chroma=1",
            "stats": "/stats", "league": "/league/reinvent_base"}


# The stream overlay is an OBS browser source: a 1920×1080 canvas by design, never opened on a tablet or a phone.
STREAM_CANVAS_ONLY = {"overlay-chroma"}


def staff_pages(event: dict[str, str]) -> dict[str, str]:
    event_id, race_id = event["event_id"], event["race_id"]
    return {"home-admin": "/", "console-events": "/console/events", "console-event-new": "/console/events/new",
            "console-event-edit": f"/console/events/{event_id}/edit",
            "console-overlay-link": f"/console/events/{event_id}/overlay", "console-fleets": "/console/fleets",
            "console-cars": "/console/cars", "console-models": "/console/models", "console-races": "/console/races",
            "console-race-edit": f"/console/races/{event_id}/{race_id}", "console-timekeeper": "/console/timekeeper",
            "console-timekeeper-track": f"/console/timekeeper/{event_id}/1",
            "console-registration": "/console/registration", "console-users": "/console/users",
            "commentator": f"/commentator/{event_id}", "registry": "/models/registry"}


# Settled: loaded, no htmx request in flight, a live page's event stream open (live.js keeps it in
# window.dremLiveStream), and two frames painted since.
SETTLED = """() => new Promise(done => requestAnimationFrame(() => requestAnimationFrame(() => {
    const holder = document.querySelector('[data-live-stream]');
    const live = holder && holder.dataset.liveStream;
    done(document.readyState === 'complete' && !document.querySelector('.htmx-request') &&
         (!live || (window.dremLiveStream !== undefined && window.dremLiveStream.readyState === EventSource.OPEN)));
})))"""


RACER_PAGES = {"home-racer": "/", "my-models": "/console/my-models", "my-races": "/console/my-races",
               "profile": "/console/profile", "booth": "/booth"}


def sign_in(page: Any, url: str, username: str, password: str) -> None:
    page.goto(url + "/login")
    page.fill("#username", username)
    page.fill("#password", password)
    page.get_by_role("button", name="Sign in").click()
    page.wait_for_url(url + "/")


def sideways(page: Any) -> tuple[int, list[str]]:
    """How far the page is wider than the window, and the first elements sticking out past its right edge (what to
    fix); a table inside its own `.table-scroll` box scrolls there, not the page."""
    found = page.evaluate("""() => {
        const width = window.innerWidth;
        const wide = [...document.querySelectorAll('body *')].filter(el => {
            const box = el.getBoundingClientRect();
            return box.width > 0 && box.right > width + 1 && !el.closest('.table-scroll');
        }).slice(0, 4).map(el => el.tagName.toLowerCase() + (el.id ? '#' + el.id : '') +
                           (typeof el.className === 'string' && el.className ? '.' + el.className.split(' ').join('.')
                            : ''));
        return [document.scrollingElement.scrollWidth - width, wide];
    }""")
    return found[0], found[1]


def look_at_every_page(chromium: Any, url: str, pages: dict[str, str], *, user: tuple[str, str] | None) -> list[str]:
    """Opens each page at each size; returns what a person would notice is wrong (empty when all is well)."""
    GALLERY.mkdir(parents=True, exist_ok=True)
    problems: list[str] = []
    for size in SIZES:
        context = chromium.new_context(viewport=size)
        context.set_default_timeout(15_000)
        page = context.new_page()
        if user:
            sign_in(page, url, *user)
        errors: list[str] = []
        page.on("console", lambda message, errors=errors: errors.append(f"console: {message.text}")
                if message.type == "error" else None)
        page.on("pageerror", lambda error, errors=errors: errors.append(f"script: {error}"))
        page.on("response", lambda response, errors=errors: errors.append(
            f"{response.status} {response.url}") if response.status >= 400 else None)
        for name, path in pages.items():
            if name in STREAM_CANVAS_ONLY and size != BIG_SCREEN:
                continue
            errors.clear()
            answer = page.goto(url + path, wait_until="load")
            page.wait_for_function(SETTLED)  # what is checked and photographed is the page as it settles
            where = f"{name} at {size['width']}x{size['height']}"
            if answer is None or answer.status != 200:
                problems.append(f"{where}: answered {answer.status if answer else 'nothing'}")
            spill, sticking_out = sideways(page)
            if spill > 1:
                problems.append(f"{where}: {spill}px wider than the screen (sideways scrolling): {sticking_out}")
            problems.extend(f"{where}: {error}" for error in errors)
            page.screenshot(path=str(GALLERY / f"{name}-{size['width']}x{size['height']}.png"))
        context.close()
    return problems


def test_public_pages_fit_every_screen_without_errors(chromium, app_url, gallery_event):
    problems = look_at_every_page(chromium, app_url, public_pages(gallery_event), user=None)
    assert problems == [], "\n".join(problems)
    # Browsers ask for /favicon.ico by themselves (a 403 there once put an error on every page's console).
    assert requests.get(app_url + "/favicon.ico", timeout=10).status_code == 200


def test_staff_pages_fit_every_screen_without_errors(chromium, app_url, live_stack, gallery_event):
    admin = (live_stack.admin_username, live_stack.admin_password)
    problems = look_at_every_page(chromium, app_url, staff_pages(gallery_event), user=admin)
    assert problems == [], "\n".join(problems)


def test_racer_pages_fit_every_screen_without_errors(chromium, app_url, gallery_event):
    problems = look_at_every_page(chromium, app_url, RACER_PAGES, user=("gallery-ana", PASSWORD))
    assert problems == [], "\n".join(problems)
