"""Shared pieces for the racer/desk/users/models console tests (HTML over conftest's `client`): browsers signed in
as a role, form posts with the CSRF token, and reading what a page shows."""
from __future__ import annotations

import re
from typing import Any

from chalice.test import Client

from tests.unit.conftest import PASSWORD, Browser, Users


def sign_in(browser: Browser, username: str, password: str = PASSWORD) -> Browser:
    browser.get("/login")
    reply = browser.post("/login", {"username": username, "password": password, "csrf_token": browser.csrf_token})
    assert reply.status_code == 303, reply.body
    return browser


def signed_in(client: Client, users: Users, username: str, *groups: str) -> Browser:
    users.create(username, groups)
    return sign_in(Browser(client), username)


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
