"""Tokens stop working within seconds of sign-out, disable, demotion or deletion (they used to live up to 1 h)."""
from __future__ import annotations

import time

import pytest

from chalicelib.auth.revocation import RevocationMark
from tests.unit.conftest import PASSWORD, bearer
from tests.unit.users_helpers import call

pytestmark = pytest.mark.unit


def _browser_session(browser, username: str):
    browser.get("/login")
    assert browser.post("/login", {"username": username, "password": PASSWORD,
                                   "csrf_token": browser.csrf_token}).status_code == 303
    return browser.cookies["drem_session"]


def test_a_copied_session_token_dies_with_sign_out(browser, client, users):
    users.create("sam", ("racer",))
    stolen = _browser_session(browser, "sam")  # e.g. read off a shared laptop
    assert client.http.get("/api/me", headers=bearer(stolen)).status_code == 200

    assert browser.post("/logout", {"csrf_token": browser.csrf_token}).status_code == 303

    assert client.http.get("/api/me", headers=bearer(stolen)).status_code == 401


def test_sign_out_does_not_end_a_new_sign_in(browser, client, users):
    users.create("sam", ("racer",))
    _browser_session(browser, "sam")
    browser.post("/logout", {"csrf_token": browser.csrf_token})

    fresh = users.sign_in("sam")["AccessToken"]  # the same second, a new sign-in

    assert client.http.get("/api/me", headers=bearer(fresh)).status_code == 200


def test_a_disabled_users_token_is_refused_at_once(client, users):
    admin = users.access_token("boss", ("admin",))
    racer = users.access_token("troublemaker", ("racer",))

    assert call(client, "POST", "/api/users/troublemaker/disable", token=admin)[0] == 200

    assert client.http.get("/api/me", headers=bearer(racer)).status_code == 401


def test_a_demoted_admins_token_loses_admin_at_once(client, users):
    boss = users.access_token("boss", ("admin",))
    second = users.access_token("second", ("admin",))
    assert client.http.get("/api/users?limit=1", headers=bearer(second)).status_code == 200

    assert call(client, "PUT", "/api/users/second/role", {"role": "racer"}, token=boss)[0] == 200

    assert client.http.get("/api/users?limit=1", headers=bearer(second)).status_code == 401
    fresh = users.sign_in("second")["AccessToken"]
    assert client.http.get("/api/me", headers=bearer(fresh)).json_body["roles"] == ["racer"]


def test_a_demoted_admins_browser_carries_on_with_the_new_role(client, browser, users):
    boss = users.access_token("boss", ("admin",))
    users.create("second", ("admin",))
    _browser_session(browser, "second")
    assert browser.get("/api/me").json_body["roles"] == ["admin"]

    call(client, "PUT", "/api/users/second/role", {"role": "racer"}, token=boss)

    me = browser.get("/api/me")  # the session renews itself from the refresh token, with the new groups
    assert me.status_code == 200 and me.json_body["roles"] == ["racer"]
    assert browser.get("/api/users?limit=1").status_code == 403


def test_a_deleted_users_token_is_refused(client, users):
    token = users.access_token("leaving", ("racer",))

    assert call(client, "DELETE", "/api/me", {"confirm": "leaving"}, token=token)[0] == 200

    assert client.http.get("/api/me", headers=bearer(token)).status_code == 401


def test_another_process_sees_the_revocation_within_the_cache_ttl(client, users, monkeypatch):
    # Another app process (another Lambda container) only learns of the mark when its cached copy expires.
    from chalicelib import services
    from chalicelib.auth.revocation import REVOKED, RevocationList

    monkeypatch.setattr(REVOKED, "_ttl_s", 0.3)
    token = users.access_token("sam", ("racer",))
    sub = client.http.get("/api/me", headers=bearer(token)).json_body["sub"]  # caches "no mark" for sam
    RevocationList().ended(services.session_store(), sub)  # written by the other process

    deadline, status = time.monotonic() + 5, 200
    while status == 200 and time.monotonic() < deadline:
        status = client.http.get("/api/me", headers=bearer(token)).status_code
    assert status == 401


@pytest.mark.parametrize(("mark", "iat", "jti", "groups", "revoked"), [
    (RevocationMark(not_before=100), 99, "a", {"racer"}, True),
    (RevocationMark(not_before=100), 100, "a", {"racer"}, False),
    (RevocationMark(not_before=100, whole_second=True), 100, "a", {"racer"}, True),
    (RevocationMark(not_before=100, whole_second=True), 101, "a", {"racer"}, False),
    (RevocationMark(not_before=100, ended_sessions=frozenset({"a"})), 100, "a", {"racer"}, True),
    (RevocationMark(not_before=100, ended_sessions=frozenset({"a"})), 100, "b", {"racer"}, False),
    (RevocationMark(not_before=100, groups=frozenset({"racer"})), 100, "a", {"admin"}, True),
    (RevocationMark(not_before=100, groups=frozenset({"racer"})), 100, "a", {"racer"}, False),
    (RevocationMark(not_before=100), None, "a", {"racer"}, True),
])
def test_which_tokens_a_mark_revokes(mark, iat, jti, groups, revoked):
    assert mark.revokes(iat, jti, frozenset(groups)) is revoked


def test_a_later_change_in_the_same_second_keeps_earlier_sign_outs():
    first = RevocationMark(not_before=100, ended_sessions=frozenset({"a"}), whole_second=True)
    combined = first.then(RevocationMark(not_before=100, groups=frozenset({"racer"})))

    assert combined.ended_sessions == {"a"} and combined.groups == {"racer"} and not combined.whole_second
    assert first.then(RevocationMark(not_before=99)).not_before == 100
    assert first.then(RevocationMark(not_before=101)) == RevocationMark(not_before=101)
