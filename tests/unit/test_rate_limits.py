"""Rate limits on sign-in (per account and per client address), sign-up and device activation: a guesser gets 429
with Retry-After and a plain message; an honest racer who mistypes a few times does not."""
from __future__ import annotations

import json

import pytest

from chalicelib.auth.rate_limits import Limit, SlidingWindow
from chalicelib.domain.errors import RateLimited
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
    refused = _token_request(client, "admin", PASSWORD)  # even the right password waits: it may be a lucky guess
    assert refused.status_code == 429 and 1 <= int(refused.headers["Retry-After"]) <= 300
    assert "Too many wrong passwords for this account" in refused.json_body["error"]["message"]


def test_guessing_from_other_addresses_is_stopped_per_account(client, users, source_ip):
    users.create("admin", ("admin",))
    for n in range(10):
        _token_request(client, "admin", f"guess-{n}", address=f"10.0.1.{n}")

    assert _token_request(client, "admin", "guess-x", address="10.0.2.1").status_code == 429


def test_one_address_spraying_many_accounts_is_stopped_per_address(client, users, source_ip):
    answers = [_token_request(client, f"user{n}", "Spray-Pass-1").status_code for n in range(31)]

    assert answers[-1] == 429 and answers.count(401) == 30
    assert _token_request(client, "someone", "x", address="10.0.0.8").status_code == 401  # another phone is fine


def test_a_racer_who_mistypes_then_gets_it_right_is_not_locked_out(client, users, source_ip):
    users.create("rita", ("racer",))
    for n in range(4):
        _token_request(client, "rita", f"typo-{n}")

    assert _token_request(client, "rita", PASSWORD).status_code == 200
    assert _token_request(client, "rita", "typo-again").status_code == 401  # the count started over


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
