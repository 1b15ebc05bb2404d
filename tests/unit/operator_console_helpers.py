"""Shared fixtures for the operator-console tests (events, cars, timekeeper, race admin): the app with the console
blueprints (added only if app.py does not register them yet), a signed-in browser session (cookies + CSRF) and the
race `Desk` for setting things up through the JSON API."""
from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import pytest
from chalice.test import Client

from tests.unit.conftest import PASSWORD, Browser, Users
from tests.unit.race_helpers import Desk, _app_with_race_routes


def app_with_console() -> Any:
    from chalicelib.routes import assignments, profiles, racer_models as models, users
    from chalicelib.routes.console import events as console_events, fleets as console_fleets
    from chalicelib.routes.console import races as console_races, timekeeper as console_timekeeper

    app = _app_with_race_routes()
    needed = ((users, "/api/signup"), (profiles, "/api/me/profile"), (models, "/api/models"),
              (assignments, "/api/cars/{device_id}/models"), (console_events, "/console/events"),
              (console_fleets, "/console/fleets"), (console_timekeeper, "/console/timekeeper"),
              (console_races, "/console/races"))
    for module, marker in needed:
        if marker not in app.routes:
            app.register_blueprint(module.bp)
    return app


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


@pytest.fixture
def console(stack: Any, users: Users, device_verifier: None,
            tmp_path_factory: pytest.TempPathFactory) -> Iterator[Console]:
    app = app_with_console()
    with Client(app, project_dir=str(tmp_path_factory.mktemp("no-chalice-config"))) as client:
        desk = Desk(client, users)
        desk.token("op", "operator")
        yield Console(desk, Browser(client), users)


def text_of(html: str) -> str:
    """The page's visible text, roughly: tags dropped, whitespace collapsed."""
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html)).strip()


def field_error(html: str, field: str) -> str | None:
    match = re.search(rf'id="{re.escape(field)}-error"[^>]*>([^<]*)<', html)
    return match.group(1) if match else None
