"""Browser sign-in with cookies: login, errors next to the field, temporary passwords, renewal and sign-out."""
from __future__ import annotations

import re

import pytest

from tests.unit.conftest import PASSWORD, cookie_attributes

pytestmark = pytest.mark.unit


def _login(browser, username: str, password: str = PASSWORD, next_path: str = "/"):
    browser.get("/login")
    return browser.post("/login", {"username": username, "password": password, "next": next_path,
                                   "csrf_token": browser.csrf_token})


def _field_error(html: str, field: str) -> str | None:
    match = re.search(rf'id="{field}-error"[^>]*>([^<]*)<', html)
    return match.group(1) if match else None


def test_login_sets_http_only_session_cookies_and_shows_the_user(browser, users):
    users.create("alice", ("racer",))

    response = _login(browser, "alice")

    assert response.status_code == 303
    assert response.headers["Location"] == "/"
    session = cookie_attributes(response.headers, "drem_session")
    refresh = cookie_attributes(response.headers, "drem_refresh")
    for cookie in (session, refresh):
        assert cookie is not None and cookie["value"]
        assert "httponly" in cookie and cookie["samesite"] == "Lax" and cookie["path"] == "/"
        assert "secure" not in cookie  # the local public URL is plain http
    home = browser.get("/")
    assert "Signed in as <strong>alice</strong>" in home.body.decode()
    assert browser.get("/api/me").json_body["username"] == "alice"


def test_session_cookies_are_secure_when_served_over_https(browser, users, monkeypatch):
    from chalicelib.settings import get_settings

    monkeypatch.setenv("DREM_PUBLIC_URL", "https://drem.example.org")
    get_settings.cache_clear()
    users.create("sam")

    response = _login(browser, "sam")

    assert "secure" in cookie_attributes(response.headers, "drem_session")
    assert "secure" in cookie_attributes(response.headers, "drem_refresh")


def test_wrong_password_is_shown_next_to_the_password_field(browser, users):
    users.create("bob")

    response = _login(browser, "bob", "Wrong-Password-1")

    assert response.status_code == 401
    html = response.body.decode()
    assert _field_error(html, "password") == "Incorrect username or password."
    assert 'value="bob"' in html  # the username is kept
    assert "drem_session" not in browser.cookies


def test_unknown_user_gets_the_same_answer_as_a_wrong_password(browser, stack):
    response = _login(browser, "nobody", "Whatever-123")

    assert response.status_code == 401
    assert _field_error(response.body.decode(), "password") == "Incorrect username or password."


def test_empty_username_is_shown_next_to_the_username_field(browser, stack):
    response = _login(browser, "   ", "x")

    assert response.status_code == 400
    assert _field_error(response.body.decode(), "username") == "Enter your username."
    too_long = _login(browser, "u" * 129, "x")
    assert too_long.status_code == 400
    assert _field_error(too_long.body.decode(), "username") == "The username is too long (at most 128 characters)."


def test_login_redirects_only_to_local_paths(browser, users):
    users.create("carol")

    assert _login(browser, "carol", next_path="/api/me").headers["Location"] == "/api/me"
    assert _login(browser, "carol", next_path="//evil.example/x").headers["Location"] == "/"
    assert _login(browser, "carol", next_path="https://evil.example").headers["Location"] == "/"


def test_api_route_answers_json_401_even_to_a_browser(client, stack):
    response = client.http.get("/api/me", headers={"Accept": "text/html"})

    assert response.status_code == 401
    assert response.json_body["error"]["message"] == "Sign in to continue."


def test_temporary_password_must_be_replaced_before_signing_in(browser, users):
    users.create("newbie", ("racer",), password="Temporary-Pass-1", temporary=True)

    first = _login(browser, "newbie", "Temporary-Pass-1")
    assert first.status_code == 303 and first.headers["Location"] == "/login/new-password"
    assert "drem_session" not in browser.cookies
    page = browser.get("/login/new-password")
    assert page.status_code == 200 and "newbie" in page.body.decode()

    mismatch = browser.post("/login/new-password", {"new_password": "Brand-New-Pass-2", "confirm_password": "x",
                                                    "csrf_token": browser.csrf_token})
    assert mismatch.status_code == 400
    assert _field_error(mismatch.body.decode(), "confirm_password") == "The two passwords differ."

    weak = browser.post("/login/new-password", {"new_password": "short", "confirm_password": "short",
                                                "csrf_token": browser.csrf_token})
    assert weak.status_code == 400
    assert "too weak" in _field_error(weak.body.decode(), "new_password")

    done = browser.post("/login/new-password", {"new_password": "Brand-New-Pass-2",
                                                "confirm_password": "Brand-New-Pass-2",
                                                "csrf_token": browser.csrf_token})
    assert done.status_code == 303 and done.headers["Location"] == "/"
    assert browser.get("/api/me").json_body["username"] == "newbie"
    assert "drem_challenge" not in browser.cookies


def test_new_password_page_without_a_challenge_goes_back_to_login(browser, stack):
    response = browser.get("/login/new-password")

    assert response.status_code == 303 and response.headers["Location"] == "/login"


def test_expired_session_is_renewed_from_the_refresh_token(browser, users):
    from tests.unit.test_auth_tokens import _expired

    users.create("dora", ("operator",))
    _login(browser, "dora")
    browser.cookies["drem_session"] = _expired(browser.cookies["drem_session"])

    response = browser.get("/api/me")

    assert response.status_code == 200
    assert response.json_body["roles"] == ["operator"]
    renewed = cookie_attributes(response.headers, "drem_session")
    assert renewed is not None and renewed["value"] != ""
    assert browser.get("/api/me").status_code == 200  # the renewed cookie works on its own


def test_session_without_access_cookie_is_renewed_from_the_refresh_cookie(browser, users):
    users.create("eve")
    _login(browser, "eve")
    del browser.cookies["drem_session"]  # the browser dropped it at Max-Age

    assert browser.get("/api/me").json_body["username"] == "eve"


def test_logout_clears_cookies_and_revokes_the_refresh_token(browser, users):
    users.create("fred")
    _login(browser, "fred")
    refresh_token = browser.cookies["drem_refresh"]

    response = browser.post("/logout", {"csrf_token": browser.csrf_token})

    assert response.status_code == 303 and response.headers["Location"] == "/login"
    assert "drem_session" not in browser.cookies and "drem_refresh" not in browser.cookies
    assert "Sign in" in browser.get("/").body.decode()
    # Replaying the old refresh cookie no longer signs anyone in.
    browser.cookies["drem_refresh"] = refresh_token
    assert browser.get("/api/me").status_code == 401
    assert "drem_refresh" not in browser.cookies  # and the dead cookie is cleared


def test_tampered_session_cookie_is_dropped_not_trusted(browser, users):
    users.create("gina", ("racer",))
    _login(browser, "gina")
    header, payload, signature = browser.cookies["drem_session"].split(".")
    browser.cookies["drem_session"] = f"{header}.{payload[:-4]}AAAA.{signature}"
    browser.cookies.pop("drem_refresh")

    response = browser.get("/api/me")

    assert response.status_code == 401
    assert cookie_attributes(response.headers, "drem_session")["max-age"] == "0"


def test_home_page_links_depend_on_role(browser, users):
    users.create("hal", ("admin",))
    anonymous_home = browser.get("/").body.decode()
    _login(browser, "hal")

    admin_home = browser.get("/").body.decode()

    assert 'href="/healthz"' not in anonymous_home
    assert 'href="/healthz"' in admin_home and "Your roles: admin." in admin_home


def test_htmx_request_gets_only_the_page_content(browser, stack):
    full = browser.get("/login").body.decode()
    partial = browser.get("/login", headers={"HX-Request": "true"}).body.decode()

    assert full.startswith("<!doctype html>") and "<form" in full
    assert "<html" not in partial and "<form" in partial


def test_login_form_escapes_user_input(browser, stack):
    response = _login(browser, '"><script>alert(1)</script>', "Wrong-Pass-1")

    html = response.body.decode()
    assert "<script>alert(1)</script>" not in html
    assert "&lt;script&gt;" in html
