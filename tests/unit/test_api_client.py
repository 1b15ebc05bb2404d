"""The CLI's API client signs in through POST /api/auth/token (real routes, in-process) and then calls as Bearer."""
from __future__ import annotations

import argparse

import pytest

from drem_local.api_client import ApiClient, ApiError, add_connection_arguments
from tests.unit.conftest import PASSWORD
from tests.unit.test_users_cli import ChaliceTransport

pytestmark = pytest.mark.unit


def client_for(client, *argv: str) -> ApiClient:
    parser = argparse.ArgumentParser()
    add_connection_arguments(parser)
    args = parser.parse_args(["--api", "http://drem.test", "--token", "", *argv])
    api = ApiClient(args.api, args.token)
    api._http.mount("http://", ChaliceTransport(client))
    api.login(args.username, args.password)
    return api


def test_username_and_password_give_a_bearer_client_that_acts_as_that_user(client, users):
    users.create("ops-olga", ("operator",))

    api = client_for(client, "--username", "ops-olga", "--password", PASSWORD)

    assert api.token.count(".") == 2  # a JWT access token, sent as Bearer from now on
    assert api.get("/api/me")["username"] == "ops-olga"


def test_a_wrong_password_is_a_clear_401(client, users):
    users.create("ops-olga", ("operator",))

    with pytest.raises(ApiError) as refused:
        client_for(client, "--username", "ops-olga", "--password", "Wrong-Password-9")

    assert refused.value.status == 401
    assert "could not sign in as 'ops-olga': Incorrect username or password." in str(refused.value)


def test_an_account_with_a_temporary_password_is_told_to_set_one(client, users):
    users.create("fresh", temporary=True)

    with pytest.raises(ApiError, match="new password is needed"):
        client_for(client, "--username", "fresh", "--password", PASSWORD)
