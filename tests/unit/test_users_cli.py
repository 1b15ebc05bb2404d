"""`drem users` against the real app in-process: requests → a transport adapter → the Chalice test client."""
from __future__ import annotations

import argparse

import pytest
import requests
from requests.adapters import BaseAdapter

from drem_local.api_client import ApiClient, ApiError, api_url
from drem_local.commands import users as users_command

pytestmark = pytest.mark.unit


class ChaliceTransport(BaseAdapter):
    """Sends each prepared request to the Chalice test client, so the CLI's HTTP requests hit the real routes."""

    def __init__(self, chalice_client) -> None:
        super().__init__()
        self._client = chalice_client

    def send(self, request, **kwargs):
        path = request.path_url
        body = request.body.encode() if isinstance(request.body, str) else (request.body or b"")
        reply = getattr(self._client.http, request.method.lower())(path, headers=dict(request.headers), body=body)
        response = requests.Response()
        response.status_code, response._content = reply.status_code, reply.body
        response.headers.update(reply.headers)
        response.url, response.request = request.url, request
        return response

    def close(self) -> None:
        pass


def _run(client, token, *argv):
    parser = argparse.ArgumentParser()
    users_command.add_arguments(parser)
    args = parser.parse_args(["--token", token, *argv])
    api_client = ApiClient(api_url(args), args.token)
    api_client._http.mount("http://", ChaliceTransport(client))
    answer = users_command._perform(api_client, args)
    return users_command.describe(args.action, answer)


def test_cli_creates_lists_changes_role_and_disables(client, users, aws_clients, stack):
    admin = users.access_token("boss", ("admin",))
    created = _run(client, admin, "create", "walk_in-7", "--email", "w7@example.test", "--country", "fr")
    assert created.startswith("Created racer walk_in-7 (FR).") and "Temporary password" in created

    listed = _run(client, admin, "list", "--prefix", "walk")
    assert listed.splitlines()[0].split()[:2] == ["walk_in-7", "FR"]

    assert _run(client, admin, "role", "walk_in-7", "operator") == "walk_in-7 is now operator."
    groups = aws_clients.cognito.admin_list_groups_for_user(UserPoolId=stack.user_pool_id, Username="walk_in-7")
    assert [g["GroupName"] for g in groups["Groups"]] == ["operator"]

    assert _run(client, admin, "disable", "walk_in-7") == "walk_in-7 is disabled."
    assert "DISABLED" in _run(client, admin, "list", "--prefix", "walk_in")


def test_cli_reports_the_api_error(client, users):
    racer = users.access_token("racer1", ("racer",))
    with pytest.raises(ApiError, match=r"needs the role .*\(HTTP 403\)"):
        _run(client, racer, "create", "someone", "--email", "s@example.test", "--country", "GB")
