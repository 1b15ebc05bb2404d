"""The console's navigation grouped by role: each signed-in person sees only the groups (and links) their roles
open, in one order, and the layout draws them as labelled lists behind a "Menu" toggle on small screens."""
from __future__ import annotations

import re
from typing import Any

import pytest

from chalicelib.core.principals import ANONYMOUS, User
from chalicelib.routes.navigation import nav_groups
from tests.unit.racer_console_helpers import body, signed_in

pytestmark = pytest.mark.unit

RACER_LINKS = ["My models", "My races", "My model versions", "Learning booth", "Profile"]
RACE_CONTROL_LINKS = ["Events", "Fleets", "Cars", "Models", "Timekeeper", "Races"]


def _user(*groups: str) -> User:
    return User(sub="00000000-0000-4000-8000-000000000001", username="someone", groups=frozenset(groups))


def _shown(*groups: str) -> dict[str, list[str]]:
    return {group.title: [link.label for link in group.links] for group in nav_groups(_user(*groups))}


def test_a_racer_sees_their_own_screens_and_no_staff_group() -> None:
    assert _shown("racer") == {"Racer": RACER_LINKS, "Results": ["League"]}


def test_registration_staff_see_the_desk_and_nothing_of_race_control_or_admin() -> None:
    assert _shown("registration") == {"Racer": RACER_LINKS, "Registration": ["Registration desk"],
                                      "Results": ["League"]}


def test_an_operator_sees_race_control_but_not_the_desk_or_admin() -> None:
    assert _shown("operator") == {"Racer": RACER_LINKS, "Race control": RACE_CONTROL_LINKS, "Results": ["League"]}


def test_an_admin_sees_every_group_in_order() -> None:
    shown = _shown("admin")
    assert list(shown) == ["Racer", "Registration", "Race control", "Admin", "Results"]
    assert shown["Admin"] == ["Users"] and shown["Race control"] == RACE_CONTROL_LINKS


def test_roles_add_up_and_nobody_signed_out_gets_a_console_nav() -> None:
    assert list(_shown("registration", "operator")) == ["Racer", "Registration", "Race control", "Results"]
    assert nav_groups(None) == [] and [g.title for g in nav_groups(ANONYMOUS)] == ["Results"]


def _nav(html: str) -> str:
    return html.split('data-testid="nav-links">')[1].split("</nav>")[0]


def test_the_racers_page_has_labelled_groups_and_no_admin_link(client: Any, users: Any) -> None:
    nav = _nav(body(signed_in(client, users, "kai", "racer").get("/")))
    titles = re.findall(r'<span class="nav-group-title" id="nav-group-([\w-]+)">([^<]+)</span>', nav)
    assert titles == [("racer", "Racer"), ("results", "Results")]
    assert '<ul aria-labelledby="nav-group-racer">' in nav  # a screen reader names each list by its group
    for staff in ("/console/users", "/console/registration", "/console/events", "/console/timekeeper", "/healthz"):
        assert f'href="{staff}"' not in nav


def test_the_admins_page_groups_every_console_link(client: Any, users: Any) -> None:
    page = body(signed_in(client, users, "root", "admin").get("/"))
    nav = _nav(page)
    assert 'id="nav-toggle"' in page and '<label for="nav-toggle" class="nav-toggle-label">Menu</label>' in page
    admin_group = nav.split('data-testid="nav-group-admin"')[1].split("</div>")[0]
    assert 'href="/console/users"' in admin_group
    race_control = nav.split('data-testid="nav-group-race-control"')[1].split("</div>")[0]
    assert all(f'href="/console/{path}"' in race_control for path in ("events", "fleets", "cars", "timekeeper",
                                                                       "races"))
