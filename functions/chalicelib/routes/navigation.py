"""The start page's links, each shown only to the callers its route allows. Add an entry when you add a page."""
from __future__ import annotations

from dataclasses import dataclass

from chalicelib.auth.access import SIGNED_IN, STAFF, Allow, as_allow
from chalicelib.auth.principals import Principal


@dataclass(frozen=True)
class NavLink:
    label: str
    href: str
    allow: Allow
    hint: str = ""


NAV_LINKS: tuple[NavLink, ...] = (
    NavLink("My account", "/api/me", SIGNED_IN, "who drem thinks you are (JSON)"),
    NavLink("Service health", "/healthz", as_allow(STAFF), "storage and local state"),
)


def links_for(principal: Principal) -> list[NavLink]:
    return [link for link in NAV_LINKS if link.allow.permits(principal)]
