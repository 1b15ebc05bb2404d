"""Issue 13, item 4: a racer self-signed-up on AWS, the emailed code never came (no SES, a mistyped address), and staff
had no way to confirm the account. An admin now sees the account waiting on the Users page and confirms it there (or
through the JSON API); the racer then signs in with the password they chose."""
from __future__ import annotations

from typing import Any

import pytest

from chalicelib.core.errors import AccountNotReady
from tests.unit.conftest import PASSWORD, Browser
from tests.unit.racer_console_helpers import body, post, sign_in, signed_in, text
from tests.unit.users_helpers import call, error_message, groups_claim, sign_up_body

pytestmark = pytest.mark.unit


def _sign_up_waiting_for_its_code(client: Any, username: str) -> None:
    status, reply = call(client, "POST", "/api/signup", sign_up_body(username))
    assert status == 201 and reply["confirmed"] is False, reply  # as on AWS: Cognito emails a code


def _row(reply: Any, username: str) -> str:
    return body(reply).split(f'data-username="{username}"')[1].split("</tr>")[0]


def test_an_admin_confirms_a_sign_up_whose_code_never_came_and_the_racer_signs_in(aws_mode: Any, client: Any,
                                                                                   users: Any) -> None:
    from chalicelib import services

    _sign_up_waiting_for_its_code(client, "kim.waits")
    with pytest.raises(AccountNotReady, match="not confirmed"):
        services.identity_provider().sign_in("kim.waits", PASSWORD)

    admin = signed_in(client, users, "root", "admin")
    page = admin.get("/console/users?q=kim")
    row = _row(page, "kim.waits")
    assert "waiting for the emailed code" in row and "UNCONFIRMED" not in row and "unconfirmed" not in row
    assert 'action="/console/users/kim.waits/confirm"' in row and ">Confirm</button>" in row

    confirmed = post(admin, "/console/users/kim.waits/confirm", htmx=True)
    assert confirmed.status_code == 200
    assert "kim.waits is confirmed and can sign in now." in text(confirmed)  # the success message, in the row
    assert 'data-testid="notice"' in body(confirmed)
    assert "waiting for the emailed code" not in body(confirmed) and ">Confirm</button>" not in body(confirmed)

    # The racer signs in with the password chosen at sign-up, as a racer.
    racer = sign_in(Browser(client), "kim.waits")
    assert racer.get("/console/my-models").status_code == 200
    assert groups_claim(users.sign_in("kim.waits")["AccessToken"]) == ["racer"]

    again = post(admin, "/console/users/kim.waits/confirm", htmx=True)
    assert again.status_code == 409 and "kim.waits is not waiting for an emailed code" in text(again)


def test_only_a_sign_up_waiting_for_its_code_can_be_confirmed(aws_mode: Any, client: Any, users: Any) -> None:
    """A desk-registered racer who has not chosen a password yet is not confirmed past that step (no button, 409)."""
    admin = signed_in(client, users, "root", "admin")
    users.create("desk.racer", ("racer",), temporary=True)
    row = _row(admin.get("/console/users?q=desk"), "desk.racer")
    assert "temporary password, not signed in yet" in row and ">Confirm</button>" not in row
    refused = post(admin, "/console/users/desk.racer/confirm", htmx=True)
    assert refused.status_code == 409 and "not waiting for an emailed code" in text(refused)
    assert post(admin, "/console/users/nobody/confirm", htmx=True).status_code == 404


def test_the_json_api_confirms_too_for_admins_only(aws_mode: Any, client: Any, users: Any) -> None:
    _sign_up_waiting_for_its_code(client, "lee.waits")
    for role in ("registration", "operator", "racer"):
        status, _ = call(client, "POST", "/api/users/lee.waits/confirm", token=users.access_token(f"{role}-x", (role,)))
        assert status == 403, role
    admin = users.access_token("api-admin", ("admin",))
    status, user = call(client, "POST", "/api/users/lee.waits/confirm", token=admin)
    assert status == 200 and user["username"] == "lee.waits" and user["status"] == "CONFIRMED"
    assert users.sign_in("lee.waits")["AccessToken"]
    status, reply = call(client, "POST", "/api/users/lee.waits/confirm", token=admin)
    assert status == 409 and "not waiting for an emailed code" in error_message(reply)
