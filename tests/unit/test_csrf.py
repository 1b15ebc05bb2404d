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


# --- the session binding and the Origin check (issue 12: a cookie planted from another port forged an admin action)

PLANTED = "planted-by-another-port-" + "p" * 24


def _signed_in_admin(browser, users):
    users.create("victim.admin", ("admin",))
    users.create("target", ("racer",))
    browser.get("/login")
    reply = browser.post("/login", {"username": "victim.admin", "password": PASSWORD,
                                    "csrf_token": browser.csrf_token})
    assert reply.status_code == 303
    return browser


def _target_enabled(aws_clients, stack) -> bool:
    return aws_clients.cognito.admin_get_user(UserPoolId=stack.user_pool_id, Username="target")["Enabled"]


def test_a_planted_csrf_cookie_cannot_forge_an_admin_action(browser, users, aws_clients, stack):
    _signed_in_admin(browser, users)
    # What a page on 127.0.0.1:<another port> can do: set drem_csrf for the host (cookies ignore ports) and post
    # a form carrying the same value; the browser adds the admin's session cookies.
    browser.cookies["drem_csrf"] = PLANTED

    reply = browser.post("/api/users/target/disable", {"csrf_token": PLANTED})

    assert reply.status_code == 403
    assert _target_enabled(aws_clients, stack)


def test_sign_in_rotates_the_csrf_token_to_one_bound_to_the_session(browser, users):
    browser.get("/login")
    before = browser.csrf_token
    _signed_in_admin(browser, users)

    assert browser.csrf_token != before and "." in browser.csrf_token
    page = browser.get("/").body.decode()
    assert f'"X-CSRF-Token": "{browser.csrf_token}"' in page


def test_a_token_of_another_session_is_refused(browser, client, users, aws_clients, stack):
    from tests.unit.conftest import Browser

    _signed_in_admin(browser, users)
    users.create("other", ("racer",))
    other = Browser(client)
    other.get("/login")
    other.post("/login", {"username": "other", "password": PASSWORD, "csrf_token": other.csrf_token})
    browser.cookies["drem_csrf"] = other.csrf_token  # a valid token, but of the attacker's own session

    reply = browser.post("/api/users/target/disable", {"csrf_token": other.csrf_token})

    assert reply.status_code == 403
    assert _target_enabled(aws_clients, stack)


@pytest.mark.parametrize("header", [{"Origin": "http://127.0.0.1:8001"}, {"Origin": "null"},
                                    {"Referer": "http://evil.example/page"}])
def test_a_post_from_another_origin_is_refused_even_with_the_right_token(browser, users, aws_clients, stack,
                                                                         header):
    _signed_in_admin(browser, users)

    reply = browser.post("/api/users/target/disable", {"csrf_token": browser.csrf_token},
                         headers={"Host": "127.0.0.1:8000", **header})

    assert reply.status_code == 403 and "another site" in reply.body.decode()
    assert _target_enabled(aws_clients, stack)


@pytest.mark.parametrize("header", [{"Origin": "http://127.0.0.1:8000"}, {"Origin": "http://192.168.1.20:8000"},
                                    {"Referer": "http://192.168.1.20:8000/console/users"}, {}])
def test_same_origin_posts_with_the_right_token_pass(browser, users, aws_clients, stack, header):
    _signed_in_admin(browser, users)
    host = (header.get("Origin") or header.get("Referer") or "http://127.0.0.1:8000").split("/")[2]

    reply = browser.post("/api/users/target/disable", {"csrf_token": browser.csrf_token},
                         headers={"Host": host, **header})

    assert reply.status_code == 200, reply.body
    assert not _target_enabled(aws_clients, stack)


def test_a_mixed_pair_of_session_cookies_does_not_carry_the_attackers_token(browser, client, users, aws_clients,
                                                                           stack):
    """Issue 27: the token was bound to the refresh cookie while the request ran as the access cookie's user. A page on
    another port of the host plants the attacker's own refresh cookie and a token bound to it beside the admin's
    access cookie; only the Origin check stopped that. Now the token must fit the session the request runs as."""
    from tests.unit.conftest import Browser

    _signed_in_admin(browser, users)
    users.create("mallory", ("racer",))
    mallory = Browser(client)
    mallory.get("/login")
    mallory.post("/login", {"username": "mallory", "password": PASSWORD, "csrf_token": mallory.csrf_token})
    browser.cookies["drem_refresh"] = mallory.cookies["drem_refresh"]  # the admin's drem_session stays
    browser.cookies["drem_csrf"] = mallory.csrf_token

    reply = browser.post("/api/users/target/disable", {"csrf_token": mallory.csrf_token})  # no Origin, no Referer

    assert reply.status_code == 403
    assert _target_enabled(aws_clients, stack)


def test_the_token_survives_the_access_token_being_renewed(browser, users, aws_clients, stack):
    """Bound to the sign-in (origin_jti), not to one access token: a page loaded before renewal still posts."""
    _signed_in_admin(browser, users)
    token = browser.csrf_token
    del browser.cookies["drem_session"]  # expired: the refresh cookie renews it on the next request

    reply = browser.post("/api/users/target/disable", {"csrf_token": token})

    assert reply.status_code == 200, reply.body
    assert not _target_enabled(aws_clients, stack)
