"""Shared pieces for the users/sign-up/profile tests (over conftest's `client`): JSON calls, bodies, claims."""
from __future__ import annotations

import json
from typing import Any

from chalice.test import Client

from tests.unit.conftest import PASSWORD, bearer

_CSRF = "t" * 43


def call(client: Client, method: str, path: str, body: Any = None, token: str | None = None) -> tuple[int, Any]:
    headers = bearer(token) if token else {"Accept": "application/json"}
    if token is None and method.upper() != "GET":
        # No Authorization header means the CSRF double-submit applies (as for a browser on the sign-up page).
        headers.update({"Cookie": f"drem_csrf={_CSRF}", "X-CSRF-Token": _CSRF})
    payload = b""
    if body is not None:
        headers["Content-Type"] = "application/json"
        payload = json.dumps(body).encode()
    response = getattr(client.http, method.lower())(path, headers=headers, body=payload)
    text = response.body.decode() if response.body else ""
    try:
        return response.status_code, json.loads(text) if text else None
    except json.JSONDecodeError:
        return response.status_code, text


def error_message(body: Any) -> str:
    return body["error"]["message"]


def sign_up_body(username: str = "fast.racer", **changes: str) -> dict[str, str]:
    return {"username": username, "email": f"{username}@example.test", "country_code": "SE", "password": PASSWORD,
            **changes}


def groups_claim(token: str) -> list[str]:
    from tests.unit.conftest import jwt_parts

    return sorted(jwt_parts(token)[1].get("cognito:groups", []))
