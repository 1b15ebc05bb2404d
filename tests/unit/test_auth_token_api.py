"""JSON sign-in for API clients (POST /api/auth/token, /api/auth/refresh), and the wrapper's CSRF exemption rules."""
from __future__ import annotations

import json
from typing import Any

import pytest
from chalice import Blueprint, Chalice
from chalice.test import Client

from chalicelib.auth.access import OPERATOR, PUBLIC, SIGNED_IN, route
from tests.unit.conftest import PASSWORD, bearer

pytestmark = pytest.mark.unit

JSON = {"Content-Type": "application/json", "Accept": "application/json"}


def post(client: Client, path: str, body: Any, headers: dict[str, str] | None = None) -> tuple[int, dict, Any]:
    reply = client.http.post(path, body=json.dumps(body).encode(), headers={**JSON, **(headers or {})})
    return reply.status_code, json.loads(reply.body) if reply.body else {}, reply.headers


def test_token_exchange_gives_bearer_tokens_that_work_without_any_csrf_token(client, users):
    users.create("tina", ("operator",))

    status, grant, headers = post(client, "/api/auth/token", {"username": "tina", "password": PASSWORD})

    assert status == 200, grant
    assert grant["token_type"] == "Bearer" and grant["expires_in"] > 0
    assert grant["access_token"] and grant["id_token"] and grant["refresh_token"]
    assert headers["Cache-Control"] == "no-store"
    me = client.http.get("/api/me", headers=bearer(grant["access_token"]))
    assert json.loads(me.body)["username"] == "tina" and json.loads(me.body)["roles"] == ["operator"]


def test_wrong_credentials_are_401_with_one_message_for_unknown_users_and_wrong_passwords(client, users):
    users.create("tina")

    wrong_password = post(client, "/api/auth/token", {"username": "tina", "password": "Wrong-Password-1"})
    unknown_user = post(client, "/api/auth/token", {"username": "nobody-here", "password": PASSWORD})
    missing = post(client, "/api/auth/token", {"username": "tina"})

    assert wrong_password[0] == unknown_user[0] == 401
    assert wrong_password[1]["error"]["message"] == unknown_user[1]["error"]["message"] == (
        "Incorrect username or password.")
    assert missing[0] == 400 and missing[1]["error"]["field"] == "password"


def test_a_temporary_password_answers_the_new_password_challenge(client, users):
    users.create("newbie", temporary=True)

    status, answer, _ = post(client, "/api/auth/token", {"username": "newbie", "password": PASSWORD})

    assert status == 200
    assert answer["challenge"] == "NEW_PASSWORD_REQUIRED" and answer["session"]
    assert "access_token" not in answer


def test_refresh_gives_a_new_working_access_token_and_a_bad_one_is_401(client, users):
    users.create("rolf", ("racer",))
    _, grant, _ = post(client, "/api/auth/token", {"username": "rolf", "password": PASSWORD})

    status, renewed, _ = post(client, "/api/auth/refresh", {"refresh_token": grant["refresh_token"]})
    bad = post(client, "/api/auth/refresh", {"refresh_token": "not-a-refresh-token"})

    assert status == 200 and renewed["token_type"] == "Bearer"
    assert json.loads(client.http.get("/api/me", headers=bearer(renewed["access_token"])).body)["username"] == "rolf"
    assert bad[0] == 401 and bad[1]["error"]["message"]


def test_csrf_exemption_is_only_for_public_routes_and_never_acts_as_the_cookie_holder(client, users, tmp_path):
    with pytest.raises(ValueError, match="only for PUBLIC"):
        route(Blueprint(__name__), "/api/x", methods=["POST"], allow={OPERATOR}, csrf=False)
    with pytest.raises(ValueError, match="only for PUBLIC"):
        route(Blueprint(__name__), "/api/x", methods=["POST"], allow=SIGNED_IN, csrf=False)

    app, bp = Chalice(app_name="csrf-exempt-check"), Blueprint(__name__)

    @route(bp, "/api/who", methods=["POST"], allow=PUBLIC, csrf=False)
    def who(principal):
        return {"kind": principal.kind}

    @route(bp, "/api/who-checked", methods=["POST"], allow=PUBLIC)
    def who_checked(principal):
        return {"kind": principal.kind}

    app.register_blueprint(bp)
    session = users.access_token("olga", ("operator",))
    with Client(app, project_dir=str(tmp_path)) as exempt_client:
        with_cookie = post(exempt_client, "/api/who", {}, {"Cookie": f"drem_session={session}"})
        checked = post(exempt_client, "/api/who-checked", {}, {"Cookie": f"drem_session={session}"})

    assert with_cookie[:2] == (200, {"kind": "anonymous"})
    assert checked[0] == 403  # the same cookie-only post to an ordinary route still needs the CSRF token


def test_a_declared_body_that_is_not_a_json_object_is_a_400_naming_the_body(client, stack):
    broken = client.http.post("/api/auth/token", body=b'{"username": ', headers=JSON)
    listed = post(client, "/api/auth/token", ["tina", PASSWORD])

    error = json.loads(broken.body)["error"]
    assert broken.status_code == 400
    assert (error["message"], error["field"]) == ("The request body is not valid JSON.", "body")
    assert listed[0] == 400 and listed[1]["error"]["message"] == "Send a JSON object."
    assert listed[1]["error"]["field"] == "body"
