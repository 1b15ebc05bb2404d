"""The site's links, each shown only to the callers its route allows (computed here, never in a template).

`links_for(principal)` feeds the start page (with hints); `nav_groups(principal)` feeds the layout's nav: the links
grouped by the role they serve (Racer, Registration, Race control, Admin, then the public results), a group shown
only when the caller may open one of its links. Every template can call `nav_groups_for(principal)` (a Jinja global
installed below), so pages of any blueprint get the same nav without passing it themselves. Add an entry when you
add a page.
"""
from __future__ import annotations

from dataclasses import dataclass

from chalicelib.auth.access import ADMIN, OPERATOR, REGISTRATION, SIGNED_IN, STAFF, Allow, as_allow
from chalicelib.core.principals import Principal
from chalicelib.domain.countries import country_label, country_name
from drem_web import render

OPERATIONS = as_allow({ADMIN, OPERATOR})


# The nav's groups, in the order the bar shows them: (key, title).
RACER, DESK, RACE_CONTROL, ADMINISTRATION, RESULTS = "racer", "registration", "race-control", "admin", "results"
GROUP_TITLES: dict[str, str] = {RACER: "Racer", DESK: "Registration", RACE_CONTROL: "Race control",
                                ADMINISTRATION: "Admin", RESULTS: "Results"}


@dataclass(frozen=True)
class NavLink:
    label: str
    href: str
    allow: Allow
    hint: str = ""
    topbar: bool = True
    group: str = RESULTS


@dataclass(frozen=True)
class NavGroup:
    key: str
    title: str
    links: tuple[NavLink, ...]


NAV_LINKS: tuple[NavLink, ...] = (
    NavLink("My models", "/console/my-models", SIGNED_IN, "upload models and see whether they are valid", group=RACER),
    NavLink("My races", "/console/my-races", SIGNED_IN, "your races and laps", group=RACER),
    NavLink("My model versions", "/models/registry", SIGNED_IN, "your model versions, evaluations and plots",
            group=RACER),
    NavLink("Learning booth", "/booth", SIGNED_IN, "drive a track, train your model, race it", group=RACER),
    NavLink("Profile", "/console/profile", SIGNED_IN, "highlight colour, avatar, password", group=RACER),
    NavLink("Registration desk", "/console/registration", as_allow({ADMIN, REGISTRATION}), "create racer accounts",
            group=DESK),
    NavLink("Events", "/console/events", OPERATIONS, "events, tracks and race settings", group=RACE_CONTROL),
    NavLink("Fleets", "/console/fleets", OPERATIONS, "groups of cars and timers", group=RACE_CONTROL),
    NavLink("Cars", "/console/cars", OPERATIONS, "cars and timers, status and commands", group=RACE_CONTROL),
    NavLink("Models", "/console/models", OPERATIONS, "all racers' models, give models to cars", group=RACE_CONTROL),
    NavLink("Timekeeper", "/console/timekeeper", OPERATIONS, "run races", group=RACE_CONTROL),
    NavLink("Races", "/console/races", OPERATIONS, "race admin: edit laps, export", group=RACE_CONTROL),
    NavLink("All model versions", "/console/models/registry", OPERATIONS,
            "every racer's model versions with lineage and evaluations", topbar=False, group=RACE_CONTROL),
    NavLink("Users", "/console/users", as_allow({ADMIN}), "search users, change roles, disable", group=ADMINISTRATION),
    NavLink("League", "/league/reinvent_base", Allow(public=True), "the virtual league (any track: /league/TRACK)"),
    NavLink("Statistics", "/stats", Allow(public=True), "events, racers and fastest laps, per country and track",
            topbar=False),
    NavLink("API", "/api/docs", Allow(public=True), "every JSON route, who may call it, and its input", topbar=False),
    NavLink("My account", "/api/me", SIGNED_IN, "who drem thinks you are (JSON)", topbar=False, group=RACER),
    NavLink("Service health", "/healthz", as_allow(STAFF), "storage and local state", topbar=False,
            group=ADMINISTRATION),
)


def links_for(principal: Principal) -> list[NavLink]:
    return [link for link in NAV_LINKS if link.allow.permits(principal)]


def topbar_links(principal: Principal | None) -> list[NavLink]:
    if principal is None:
        return []
    return [link for link in links_for(principal) if link.topbar]


def nav_groups(principal: Principal | None) -> list[NavGroup]:
    """The bar's links by group, in GROUP_TITLES order; a group none of whose links the caller may open is left out
    (a racer sees no Race control or Admin heading at all)."""
    shown = topbar_links(principal)
    groups = [NavGroup(key, title, tuple(link for link in shown if link.group == key))
              for key, title in GROUP_TITLES.items()]
    return [group for group in groups if group.links]


# One environment per process (cached): every page rendered after this import gets the role-aware nav.
render.environment().globals["nav_groups_for"] = nav_groups
render.environment().filters["country_name"] = country_name
render.environment().filters["country_label"] = country_label
