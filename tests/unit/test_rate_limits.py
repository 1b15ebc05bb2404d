"""Rate limits on sign-in (per account and per client address), sign-up and device activation: a guesser gets 429
with Retry-After and a plain message; an honest racer who mistypes a few times does not."""
from __future__ import annotations

import json

import pytest

from chalicelib.auth.rate_limits import Limit, SlidingWindow
from chalicelib.core.errors import RateLimited
from tests.unit.conftest import PASSWORD
from tests.unit.users_helpers import call, sign_up_body

pytestmark = pytest.mark.unit


def _token_request(client, username: str, password: str, address: str = "10.0.0.7"):
    return client.http.post("/api/auth/token", headers={"Content-Type": "application/json",
                                                        "X-Test-Source-Ip": address},
                            body=json.dumps({"username": username, "password": password}).encode())


@pytest.fixture
def source_ip(monkeypatch):
    """The Chalice test client reports one fixed sourceIp; let a header pick it, as distinct phones would."""
    from chalicelib.auth import rate_limits

    original = rate_limits.client_address

    def address(request):
        return request.headers.get("x-test-source-ip") or original(request)

    monkeypatch.setattr(rate_limits, "client_address", address)
    for module in ("chalicelib.routes.login", "chalicelib.routes.users", "chalicelib.routes.devices",
                   "chalicelib.routes.console.racer"):
        monkeypatch.setattr(f"{module}.client_address", address)


def test_password_guessing_at_the_admin_is_stopped_with_429_and_retry_after(client, users, source_ip):
    users.create("admin", ("admin",))
    answers = [_token_request(client, "admin", f"guess-{n}").status_code for n in range(12)]

    assert answers[:10] == [401] * 10 and answers[10:] == [429, 429]
    refused = _token_request(client, "admin", PASSWORD)  # from a new browser it may be a lucky guess: not checked
    assert refused.status_code == 429 and 1 <= int(refused.headers["Retry-After"]) <= 60
    assert "Too many wrong passwords for this account" in refused.json_body["error"]["message"]


def test_guessing_from_other_addresses_is_stopped_per_account(client, users, source_ip):
    users.create("admin", ("admin",))
    for n in range(10):
        _token_request(client, "admin", f"guess-{n}", address=f"10.0.1.{n}")

    assert _token_request(client, "admin", "guess-x", address="10.0.2.1").status_code == 429


def test_a_guesser_gets_at_most_10_checks_a_minute_per_account(client, users, source_ip, monkeypatch):
    """Issue 27's goal: however fast one address guesses, 10 passwords a minute per account are checked, no more."""
    from chalicelib.auth import rate_limits

    now = [1000.0]
    monkeypatch.setattr(rate_limits.GUESSES_PER_ACCOUNT, "_clock", lambda: now[0])
    users.create("rita", ("racer",))
    checked = []
    for minute in range(3):
        answers = [_token_request(client, "rita", f"guess-{minute}-{n}", address=f"10.0.3.{minute}").status_code
                   for n in range(25)]
        checked.append(answers.count(401))
        assert set(answers) == {401, 429}
        # The right password, from the guesser's new browser: not even checked.
        lucky = _token_request(client, "rita", PASSWORD, address=f"10.0.3.{minute}")
        assert lucky.status_code == 429
        now[0] += 61

    assert checked == [10, 10, 10]


def test_one_phone_spraying_made_up_names_locks_nobody_else_out(client, users, source_ip):
    """Issue 27: 31 wrong passwords for made-up names from one phone made every racer and the admin get 429."""
    users.create("admin", ("admin",))
    users.create("rita", ("racer",))
    answers = [_token_request(client, f"user{n}", "Spray-Pass-1").status_code for n in range(31)]

    assert answers.count(401) == 30 and answers[-1] == 429  # the sprayer is told to slow down
    # Everyone else shares the phone's address (one NAT, or the same WiFi) and signs in at the first try.
    assert _token_request(client, "rita", PASSWORD).status_code == 200
    assert _token_request(client, "admin", PASSWORD).status_code == 200
    assert _token_request(client, "someone", "x", address="10.0.0.8").status_code == 401  # another phone is fine


def test_a_racer_who_mistypes_then_gets_it_right_is_not_locked_out(client, users, source_ip):
    users.create("rita", ("racer",))
    for n in range(4):
        _token_request(client, "rita", f"typo-{n}")

    assert _token_request(client, "rita", PASSWORD).status_code == 200
    assert _token_request(client, "rita", "typo-again").status_code == 401


def _browser_sign_in(browser, username: str, password: str):
    browser.get("/login")
    return browser.post("/login", {"username": username, "password": password, "csrf_token": browser.csrf_token})


def test_nobody_can_lock_the_admin_out(browser, client, users, source_ip):
    """Issue 27: 10 wrong passwords and the admin's right one got 429 for 5 minutes, repeatable for ever. The
    admin's browser signed in before, so its right password is checked first, while the guessing goes on."""
    users.create("admin", ("admin",))
    assert _browser_sign_in(browser, "admin", PASSWORD).status_code == 303
    assert "drem_device" in browser.cookies
    browser.post("/logout", {"csrf_token": browser.csrf_token})

    for round_ in range(3):
        guesses = [_token_request(client, "admin", f"guess-{round_}-{n}").status_code for n in range(15)]
        assert guesses[-1] == 429
        signed_in = _browser_sign_in(browser, "admin", PASSWORD)
        assert signed_in.status_code == 303 and "drem_session" in browser.cookies
        browser.post("/logout", {"csrf_token": browser.csrf_token})


def test_a_device_cookie_vouches_for_its_own_account_only(browser, client, users, source_ip):
    users.create("admin", ("admin",))
    users.create("mallory", ("racer",))
    assert _browser_sign_in(browser, "mallory", PASSWORD).status_code == 303
    browser.post("/logout", {"csrf_token": browser.csrf_token})
    device = browser.cookies["drem_device"]
    for n in range(10):
        _token_request(client, "admin", f"guess-{n}")

    with_cookie = client.http.post("/api/auth/token", headers={"Content-Type": "application/json",
                                                               "Cookie": f"drem_device={device}"},
                                   body=json.dumps({"username": "admin", "password": "guess-x"}).encode())
    forged = client.http.post("/api/auth/token", headers={"Content-Type": "application/json",
                                                          "Cookie": f"drem_device={device[:-2]}xx"},
                              body=json.dumps({"username": "mallory", "password": "guess-y"}).encode())

    assert with_cookie.status_code == 429  # mallory's browser is new to the admin account
    assert forged.status_code == 401  # a tampered cookie is just a new browser (mallory's budget is untouched)


def test_a_known_browser_still_answers_for_its_own_wrong_passwords(browser, users, source_ip):
    users.create("rita", ("racer",))
    assert _browser_sign_in(browser, "rita", PASSWORD).status_code == 303
    browser.post("/logout", {"csrf_token": browser.csrf_token})

    answers = [_browser_sign_in(browser, "rita", f"typo-{n}").status_code for n in range(11)]

    assert answers[:10] == [401] * 10 and answers[10] == 429


def test_the_login_form_shows_the_limit_next_to_the_password(browser, users, source_ip):
    users.create("admin", ("admin",))
    browser.get("/login")
    for n in range(11):
        reply = browser.post("/login", {"username": "admin", "password": f"guess-{n}",
                                        "csrf_token": browser.csrf_token})

    assert reply.status_code == 429 and int(reply.headers["Retry-After"]) > 0
    assert "Too many wrong passwords for this account" in reply.body.decode()


def test_sign_up_flood_from_one_address_is_limited(client, source_ip):
    answers = [call(client, "POST", "/api/signup", sign_up_body(f"flood{n}"))[0] for n in range(21)]

    assert answers[:20] == [201] * 20 and answers[20] == 429


def test_activation_code_guessing_is_limited(client, stack, source_ip):
    def guess(n: int):
        return client.http.post("/api/devices/activate", headers={"Content-Type": "application/json"},
                                body=json.dumps({"code": f"ABCD-{n:04d}", "hostname": "car-1",
                                                 "device_kind": "car"}).encode())

    answers = [guess(n).status_code for n in range(11)]

    assert answers[:10] == [400] * 10 and answers[10] == 429


def test_a_valid_activation_code_is_never_refused_for_someone_elses_wrong_codes(api, source_ip):
    """Issue 27: about 10 bad codes from the venue's address and a valid car's activation was refused for 10 minutes.
    Codes carry 100 random bits, so a valid one is checked first; the limit only slows a wrong-code flood."""
    code = api.activation_code(api.fleet(), "car-01")
    for n in range(12):
        api.post("/api/devices/activate", {"code": f"ABCD-{n:04d}", "hostname": "x", "device_kind": "car"},
                 as_=None)

    valid = api.post("/api/devices/activate", {"code": code, "hostname": "car-01", "device_kind": "car"}, as_=None)

    assert valid.status_code == 201


def test_a_window_forgets_events_older_than_its_length():
    now = [1000.0]
    window = SlidingWindow(Limit(2, 60, "tries"), clock=lambda: now[0])
    window.record("k")
    window.record("k")
    with pytest.raises(RateLimited) as limited:
        window.require("k")
    assert limited.value.retry_after == 61

    now[0] += 60.5
    window.require("k")  # both events are older than the window now
