"""Shared pieces for the racer/desk/users/models console tests (HTML over the Chalice test client): the app with
those console blueprints, browsers signed in as a role, and reading what a page shows."""
from __future__ import annotations

import re
from typing import Any

import pytest
from chalice.test import Client

from tests.unit.conftest import PASSWORD, Browser, Users

CONSOLE_PROBES = {"console_racer": "/console/profile", "console_registration": "/console/registration",
                  "console_users": "/console/users", "console_models": "/console/models"}


def ensure_console_blueprints(app: Any) -> None:
    """Register the console blueprints unless app.py already does (a blueprint registers once per process)."""
    import importlib

    for module_name, probe in CONSOLE_PROBES.items():
        if probe not in app.routes:
            app.register_blueprint(importlib.import_module(f"chalicelib.routes.{module_name}").bp)


@pytest.fixture
def console(client: Client, chalice_app: Any) -> Client:
    ensure_console_blueprints(chalice_app)
    return client


def sign_in(browser: Browser, username: str, password: str = PASSWORD) -> Browser:
    browser.get("/login")
    reply = browser.post("/login", {"username": username, "password": password, "csrf_token": browser.csrf_token})
    assert reply.status_code == 303, reply.body
    return browser


def signed_in(console: Client, users: Users, username: str, *groups: str) -> Browser:
    users.create(username, groups)
    return sign_in(Browser(console), username)


def post(browser: Browser, path: str, form: dict[str, Any] | None = None, *, htmx: bool = False) -> Any:
    """A form post as the page sends it: the CSRF token in a hidden field (htmx also sends the header)."""
    headers = {"HX-Request": "true", "X-CSRF-Token": browser.csrf_token} if htmx else {}
    return browser.post(path, {**(form or {}), "csrf_token": browser.csrf_token}, headers=headers)


def body(reply: Any) -> str:
    return reply.body.decode() if isinstance(reply.body, bytes) else reply.body


def text(reply: Any) -> str:
    """The visible text of an HTML answer (tags dropped, whitespace collapsed)."""
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", body(reply))).strip()


def field_error(reply: Any, field: str) -> str | None:
    found = re.search(rf'<p class="field-error" id="{field}-error" role="alert">(.*?)</p>', body(reply), re.S)
    return found.group(1).strip() if found else None
