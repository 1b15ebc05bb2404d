"""A small fuzz over every declared route (the same list the OpenAPI document and the authorization matrix use):
path parameters Python's int() cannot read or that are absurdly long, query strings with '²' and foreign page tokens,
and JSON bodies nested 100,000 deep. Whatever the route, the answer is a clear 4xx, never a 500/502."""
from __future__ import annotations

import re
from typing import Any

import pytest

from chalicelib.auth.access import declared_routes
from chalicelib.core.principals import Role
from tests.unit.authz_principals import World

pytestmark = [pytest.mark.unit, pytest.mark.one_stack_per_module]  # the fuzz calls as `world`'s principals

HOSTILE_PATH_VALUES = ["9" * 4_301, "%C2%B2", "x" * 5_000, "..%2F..%2Fetc%2Fpasswd", "%00"]
HOSTILE_QUERY = "limit=%C2%B2&next=garbage&track=%C2%B2&since=%C2%B2&prefix=%00&page=" + "9" * 4_301
DEEP_JSON = b"[" * 100_000 + b"]" * 100_000
# The principal that passes each route's allow-list, so the hostile input reaches the code behind it.
CALLER_FOR_ROLE = {Role.ADMIN: "admin", Role.OPERATOR: "operator", Role.REGISTRATION: "registration",
                   Role.COMMENTATOR: "commentator", Role.RACER: "racer_a", Role.CAR: "car_x", Role.TIMER: "car_x"}


def _caller(route: Any) -> str:
    if route.allow.public or route.allow.signed_in or Role.ADMIN in route.allow.roles:
        return "admin"
    return next(CALLER_FOR_ROLE[role] for role in sorted(route.allow.roles) if role in CALLER_FOR_ROLE)


def _calls(app: Any) -> list[tuple[str, str, str, bytes | None]]:
    calls = []
    for route in declared_routes(app):
        has_params = "{" in route.path
        if has_params:
            for value in HOSTILE_PATH_VALUES:
                calls.append((route.method, re.sub(r"\{[^}]+\}", value, route.path), _caller(route), None))
        if route.method == "GET":
            calls.append((route.method, re.sub(r"\{[^}]+\}", "x", route.path) + "?" + HOSTILE_QUERY,
                          _caller(route), None))
        elif route.docs.body is not None:
            calls.append((route.method, re.sub(r"\{[^}]+\}", "x", route.path), _caller(route), DEEP_JSON))
    return calls


def test_no_route_answers_hostile_input_with_a_server_error(world: World, chalice_app: Any) -> None:
    failures = []
    calls = _calls(chalice_app)
    assert len(calls) > 100, "the fuzz must cover the API, not a handful of routes"
    for method, path, caller, body in calls:
        headers = {**world.headers[caller], "Content-Type": "application/json"}
        response = getattr(world.client.http, method.lower())(path, headers=headers, body=body or b"")
        if response.status_code >= 500:
            failures.append(f"{method} {path[:80]} as {caller}: {response.status_code} {response.body[:160]!r}")
    assert failures == []
