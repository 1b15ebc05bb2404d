"""The site's links, each shown only to the callers its route allows (computed here, never in a template).

`links_for(principal)` feeds the start page (with hints); `topbar_links(principal)` feeds the layout's nav. Every
template can call `nav_links_for(principal)` (a Jinja global installed below), so pages of any blueprint get the
same nav without passing it themselves. Add an entry when you add a page.
"""
from __future__ import annotations

from dataclasses import dataclass

from chalicelib.auth.access import ADMIN, OPERATOR, REGISTRATION, SIGNED_IN, STAFF, Allow, as_allow
from chalicelib.auth.principals import Principal
from chalicelib.domain.countries import country_name
from drem_web import render

OPERATIONS = as_allow({ADMIN, OPERATOR})


@dataclass(frozen=True)
class NavLink:
    label: str
    href: str
    allow: Allow
    hint: str = ""
    topbar: bool = True


NAV_LINKS: tuple[NavLink, ...] = (
    NavLink("My models", "/console/my-models", SIGNED_IN, "upload models and see whether they are valid"),
    NavLink("My races", "/console/my-races", SIGNED_IN, "your races and laps"),
    NavLink("My model versions", "/models/registry", SIGNED_IN, "your model versions, evaluations and plots"),
    NavLink("Profile", "/console/profile", SIGNED_IN, "highlight colour, avatar, password"),
    NavLink("Registration", "/console/registration", as_allow({ADMIN, REGISTRATION}), "create racer accounts"),
    NavLink("Events", "/console/events", OPERATIONS, "events, tracks and race settings"),
    NavLink("Fleets", "/console/fleets", OPERATIONS, "groups of cars and timers"),
    NavLink("Cars", "/console/cars", OPERATIONS, "cars and timers, status and commands"),
    NavLink("Models", "/console/models", OPERATIONS, "all racers' models, give models to cars"),
    NavLink("Timekeeper", "/console/timekeeper", OPERATIONS, "run races"),
    NavLink("Races", "/console/races", OPERATIONS, "race admin: edit laps, export"),
    NavLink("All model versions", "/console/models/registry", OPERATIONS,
            "every racer's model versions with lineage and evaluations", topbar=False),
    NavLink("Users", "/console/users", as_allow({ADMIN}), "search users, change roles, disable"),
    NavLink("League", "/league/reinvent_base", Allow(public=True), "the virtual league (any track: /league/TRACK)"),
    NavLink("Statistics", "/stats", Allow(public=True), "events, racers and fastest laps, per country and track",
            topbar=False),
    NavLink("API", "/api/docs", Allow(public=True), "every JSON route, who may call it, and its input", topbar=False),
    NavLink("My account", "/api/me", SIGNED_IN, "who drem thinks you are (JSON)", topbar=False),
    NavLink("Service health", "/healthz", as_allow(STAFF), "storage and local state", topbar=False),
)


def links_for(principal: Principal) -> list[NavLink]:
    return [link for link in NAV_LINKS if link.allow.permits(principal)]


def topbar_links(principal: Principal | None) -> list[NavLink]:
    if principal is None:
        return []
    return [link for link in links_for(principal) if link.topbar]


# One environment per process (cached): every page rendered after this import gets the role-aware nav.
render.environment().globals["nav_links_for"] = topbar_links
render.environment().filters["country_name"] = country_name
