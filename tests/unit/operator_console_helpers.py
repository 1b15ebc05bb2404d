"""Shared pieces for the operator-console tests (events, cars, timekeeper, race admin): `Console` (their fixture,
`console`, is in conftest.py) is a signed-in browser session (cookies + CSRF) with the race `Desk` for setting things
up through the JSON API; and reading what a page shows."""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from tests.unit.conftest import PASSWORD, Browser, Users
from tests.unit.race_helpers import Desk


@dataclass
class Console:
    desk: Desk
    web: Browser
    users: Users

    def sign_in(self, username: str, *groups: str) -> Browser:
        self.users.create(username, tuple(groups))
        self.web.get("/login")
        reply = self.web.post("/login", {"username": username, "password": PASSWORD, "next": "/",
                                         "csrf_token": self.web.csrf_token})
        assert reply.status_code == 303, reply.body
        return self.web

    def post(self, path: str, form: dict[str, str], *, htmx: bool = False) -> Any:
        headers = {"HX-Request": "true"} if htmx else {}
        return self.web.post(path, {**form, "csrf_token": self.web.csrf_token}, headers=headers)


def text_of(html: str) -> str:
    """The page's visible text, roughly: tags dropped, whitespace collapsed."""
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html)).strip()


def field_error(html: str, field: str) -> str | None:
    match = re.search(rf'id="{re.escape(field)}-error"[^>]*>([^<]*)<', html)
    return match.group(1) if match else None
