"""Every URL the app hands a browser works when the site lives under a path prefix: on the execute-api host (stage
`/api`, the stage only in API Gateway's request context) and behind a reverse proxy at `/drem` (X-Forwarded-Prefix).

An admin, a racer and an anonymous visitor each sign in through the form (or not) and crawl everything reachable
from the nav and the public pages (landing, leaderboard, overlay, commentator, statistics, league): every href, src,
form action, hx-* URL, data-*-url, Location and HX-Redirect is collected (tests/unit/front_door.py), and each must
start with the prefix and answer. The crawl follows the URLs themselves, so a link missed by the URL helper is both
reported (it does not start with the prefix) and refused by the door (the real front door would not route it).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from chalicelib.core.principals import User
from chalicelib.routes.navigation import links_for
from tests.unit.conftest import PASSWORD
from tests.unit.front_door import Crawler, FrontDoor, api_gateway_stage, reverse_proxy

DOORS: dict[str, Callable[[Any], FrontDoor]] = {"api-gateway-stage": api_gateway_stage, "reverse-proxy": reverse_proxy}
# Links to another site a page may show (none today); everything else must be the app's own, under the prefix.
ELSEWHERE = ("https://", "http://", "mailto:", "#", "data:")


@pytest.fixture
def racing_event(scenario) -> str:
    """An event with a racer on track 1 and a race with laps: the public pages and race pages have content."""
    scenario.add_racers("vera").add_event().add_race("vera", laps=[12_000, 11_500])
    return scenario.event_id


def nav_paths(username: str, group: str) -> set[str]:
    return {link.href for link in links_for(User(sub=username, username=username, groups=frozenset({group})))}


def assert_every_url_under(crawler: Crawler, prefix: str) -> None:
    wrong = sorted({f"{found.kind}={found.url} (on {found.found_on})" for found in crawler.found
                    if not found.url.startswith(ELSEWHERE) and not found.url.startswith(prefix + "/")})
    assert wrong == [], f"URLs outside {prefix}/:\n" + "\n".join(wrong)
    broken = sorted(f"{method} {url} → {status}" for method, answers in (("GET", crawler.answers),
                                                                         ("POST", crawler.posted))
                    for url, status in answers.items() if status in (404, 405) or status >= 500)
    assert broken == [], "URLs that do not answer:\n" + "\n".join(broken)
    assert crawler.door.outside_prefix == [], "requests that left the prefix"
    assert crawler.base_metas == {prefix}, "scripts read the base path from <meta name=drem-base>"


@pytest.mark.parametrize("door_name", list(DOORS))
def test_admin_pages_work_under_the_prefix(door_name, chalice_app, users, racing_event):
    door = DOORS[door_name](chalice_app)
    prefix = door.prefix
    users.create("ada", ("admin",))
    admin = Crawler(door)

    # An expired or missing session is sent to sign in, and back to the page asked for, under the prefix.
    signed_in = admin.sign_in("ada", PASSWORD, then=f"{prefix}/console/events")
    assert signed_in.header("location") == f"{prefix}/console/events"

    # A form posted by htmx answers with HX-Redirect (and Location for a plain browser), both under the prefix.
    fleets = admin.request("GET", f"{prefix}/console/fleets")
    csrf = admin.cookies["drem_csrf"]
    created = admin.request("POST", f"{prefix}/console/fleets", form={"name": "Track 1 cars", "csrf_token": csrf},
                            htmx=True)
    assert fleets.status == 200 and created.status == 303, created.body[:300]
    # Both answers hold URLs under this request's base path: a shared cache must not hand them to another prefix.
    assert all("X-Forwarded-Prefix" in (reply.header("vary") or "") for reply in (fleets, created))
    assert created.header("hx-redirect") == created.header("location") == f"{prefix}/console/fleets?done=fleet-created"

    admin.crawl([f"{prefix}/", f"{prefix}/leaderboard/{racing_event}", f"{prefix}/overlay/{racing_event}",
                 f"{prefix}/event/{racing_event}", f"{prefix}/commentator/{racing_event}",
                 f"{prefix}/console/races/{racing_event}/{_race_id(admin, prefix, racing_event)}"])

    assert_every_url_under(admin, prefix)
    visited = set(admin.answers)
    assert {prefix + path for path in nav_paths("ada", "admin")} <= visited, "every nav link was followed"
    assert any(url.startswith(f"{prefix}/leaderboard/{racing_event}/live") for url in visited), "the board's poll URL"
    assert any(url.startswith(f"{prefix}/overlay/{racing_event}/live") for url in visited), "the overlay's poll URL"
    assert any(url.startswith(f"{prefix}/static/") for url in visited), "stylesheets and scripts"
    assert len(visited) > 60 and len(admin.posted) > 10, f"the crawl reached only {len(visited)} URLs"


@pytest.mark.parametrize("door_name", list(DOORS))
def test_racer_and_public_pages_work_under_the_prefix(door_name, chalice_app, racing_event):
    door = DOORS[door_name](chalice_app)
    prefix = door.prefix

    visitor = Crawler(door)
    visitor.crawl([f"{prefix}/", f"{prefix}/leaderboard/{racing_event}", f"{prefix}/overlay/{racing_event}",
                   f"{prefix}/event/{racing_event}", f"{prefix}/stats", f"{prefix}/league/reinvent_base"])
    assert_every_url_under(visitor, prefix)
    assert f"{prefix}/login" in visitor.answers

    racer = Crawler(door)
    assert racer.sign_in("vera", PASSWORD, then=f"{prefix}/console/my-races").header("location") == \
        f"{prefix}/console/my-races"
    racer.crawl([f"{prefix}/"])
    assert_every_url_under(racer, prefix)
    assert {prefix + path for path in nav_paths("vera", "racer")} <= set(racer.answers)
    # Signing out sends the browser to the sign-in page under the prefix.
    signed_out = racer.request("POST", f"{prefix}/logout", form={"csrf_token": racer.cookies["drem_csrf"]})
    assert signed_out.header("location") == f"{prefix}/login"


def _race_id(crawler: Crawler, prefix: str, event_id: str) -> str:
    """The race the scenario made, as the races page links it (only through the page: no shortcut past the door)."""
    page = crawler.request("GET", f"{prefix}/console/races?event_id={event_id}")
    marker = f'{prefix}/console/races/{event_id}/'
    start = page.body.index(marker) + len(marker)
    return page.body[start:page.body.index('"', start)].split("/")[0]


def test_a_live_fragment_is_cached_per_base_path(chalice_app, client, racing_event):
    """Every spectator of one board version shares one rendered fragment, but its poll URL names the base path:
    reached at the root, on the execute-api host and through the proxy, each copy polls under its own."""
    live = f"/leaderboard/{racing_event}/live"
    at_root = client.http.get(live, headers={"HX-Request": "true"})
    assert at_root.status_code == 200 and f'hx-get="{live}' in at_root.body.decode()
    for door in (api_gateway_stage(chalice_app), reverse_proxy(chalice_app)):
        reply = Crawler(door).request("GET", door.prefix + live, htmx=True)
        assert reply.status == 200 and f'hx-get="{door.prefix}{live}' in reply.body, reply.body[:400]


def test_the_qr_code_of_a_board_behind_the_proxy_opens_the_landing_page_under_the_sub_path(
        chalice_app, racing_event, monkeypatch):
    from chalicelib.settings import get_settings

    # The organiser names the public address and the sub-path the proxy serves drem under (docs/operations.md).
    monkeypatch.setenv("DREM_PUBLIC_URL", "https://events.example.org")
    monkeypatch.setenv("DREM_BASE_PATH", "/drem")
    get_settings.cache_clear()
    door = reverse_proxy(chalice_app)
    board = Crawler(door).request("GET", f"/drem/leaderboard/{racing_event}?qr=footer")
    assert board.status == 200
    shown = board.body.split('<span class="qr-url">')[1].split("</span>")[0]
    assert shown.startswith(f"https://events.example.org/drem/event/{racing_event}")
    landing = Crawler(door).request("GET", shown.removeprefix("https://events.example.org"))
    assert landing.status == 200 and "Summit Stockholm 2026" in landing.body
    get_settings.cache_clear()
