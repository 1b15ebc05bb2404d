"""Double-submit CSRF: cookie-authenticated (and anonymous) form posts need the token; Bearer calls do not."""
from __future__ import annotations

import pytest

from tests.unit.conftest import PASSWORD, bearer, cookie_attributes

pytestmark = pytest.mark.unit


def test_first_visit_gets_a_strict_http_only_csrf_cookie_matching_the_page(browser, stack):
    response = browser.get("/login")

    cookie = cookie_attributes(response.headers, "drem_csrf")
    assert cookie["samesite"] == "Strict" and "httponly" in cookie and len(cookie["value"]) >= 32
    html = response.body.decode()
    assert f'name="csrf_token" value="{cookie["value"]}"' in html
    assert f'hx-headers=\'{{"X-CSRF-Token": "{cookie["value"]}"}}\'' in html


def test_csrf_cookie_is_kept_across_requests(browser, stack):
    first = browser.get("/login")
    second = browser.get("/")

    assert cookie_attributes(first.headers, "drem_csrf") is not None
    assert cookie_attributes(second.headers, "drem_csrf") is None


@pytest.mark.parametrize("submitted", [None, "", "wrong-token-" + "x" * 40])
def test_login_form_without_the_right_token_is_403(browser, users, submitted):
    users.create("alice")
    browser.get("/login")
    form = {"username": "alice", "password": PASSWORD}
    if submitted is not None:
        form["csrf_token"] = submitted

    response = browser.post("/login", form)

    assert response.status_code == 403
    assert "Reload the page" in response.body.decode()
    assert "drem_session" not in browser.cookies


def test_login_without_any_csrf_cookie_is_403(client, users):
    users.create("alice")

    response = client.http.post("/login", headers={"Content-Type": "application/x-www-form-urlencoded"},
                                body=f"username=alice&password={PASSWORD}&csrf_token=abc".encode())

    assert response.status_code == 403


def test_token_in_the_htmx_header_is_accepted(browser, users):
    users.create("alice")
    browser.get("/login")

    response = browser.post("/login", {"username": "alice", "password": PASSWORD},
                            headers={"X-CSRF-Token": browser.csrf_token})

    assert response.status_code == 303


def test_signed_in_logout_needs_the_token(browser, users):
    users.create("alice")
    browser.get("/login")
    browser.post("/login", {"username": "alice", "password": PASSWORD, "csrf_token": browser.csrf_token})

    forged = browser.post("/logout", {"csrf_token": "attacker-guess-" + "y" * 40})
    assert forged.status_code == 403
    assert browser.get("/api/me").status_code == 200  # still signed in

    real = browser.post("/logout", {"csrf_token": browser.csrf_token})
    assert real.status_code == 303
    assert browser.get("/api/me").status_code == 401


def test_bearer_authenticated_post_is_exempt(client, users):
    token = users.access_token("alice")

    response = client.http.post("/logout", headers=bearer(token))

    assert response.status_code == 303
