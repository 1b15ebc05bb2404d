"""The authorization matrix: every route × the eleven principals, called with real credentials, against
`tests/unit/authz_table.py`. deny ⇔ 401/403 (deny404: 401/403/404); allow ⇔ an answer below 500 that is neither
401 nor 403 (a 500 proves nothing about access: the route crashed)."""
from __future__ import annotations

import re

import pytest

from tests.unit.authz_principals import PRINCIPALS, World, full_app
from tests.unit.authz_table import TABLE, Call

pytestmark = [pytest.mark.unit, pytest.mark.one_stack_per_module]  # ~900 calls as `world`'s principals

DENIED = {"deny": {401, 403}, "deny404": {401, 403, 404}}
_PARAM = re.compile(r"{([^}]+)}")


def concrete_path(template: str, params: dict[str, str]) -> str:
    return _PARAM.sub(lambda m: params.get(m.group(1), f"matrix-{m.group(1)}"), template)


def scenario_for(world: World, key: tuple[str, str], principal: str) -> Call:
    """What the call as `principal` needs. An allowed caller acts, so it meets an object of its own (and, for a
    route that uses up its caller, is a fresh principal). The callers a route refuses ("deny") all meet ONE object
    built for them: a refused call changes nothing, so the object is as good for the next one. A call let through by
    mistake fails its own test, and the refused ones after it that find the object gone get a 404, which "deny" does
    not accept, so they fail too; "deny404" would accept it, so those callers get objects of their own. Building the
    scenario again for every refused principal was most of the matrix's time (an upload, an event, a race)."""
    case = TABLE[key]
    if case.build is None:
        return Call()
    if case.expect[principal] != "deny" or case.fresh_for_each_caller:
        return case.build(world, principal)
    if key not in world.refused_scenarios:
        world.refused_scenarios[key] = case.build(world, principal)
    return world.refused_scenarios[key]


def table_mismatch(app, table) -> str:
    """"" when the table has exactly the app's routes; else a message naming the missing and stale ones."""
    app_routes = {(method, path) for path, by_method in app.routes.items() for method in by_method}
    missing, stale = sorted(app_routes - table.keys()), sorted(table.keys() - app_routes)
    if not missing and not stale:
        return ""
    return ("tests/unit/authz_table.py must have exactly one entry per route.\n"
            f"Routes without an entry (add who may call them): {missing}\n"
            f"Entries for routes that do not exist (remove them): {stale}")


def test_the_table_lists_exactly_the_app_routes(chalice_app):
    assert table_mismatch(full_app(chalice_app), TABLE) == ""


def test_a_new_route_without_an_entry_and_a_stale_entry_are_both_named():
    from chalice import Blueprint, Chalice

    from chalicelib.auth.access import PUBLIC, route

    app, bp = Chalice(app_name="authz-table-check"), Blueprint(__name__)

    @route(bp, "/api/listed", allow=PUBLIC)
    def listed(principal):
        return {}

    @route(bp, "/api/brand-new", methods=["POST"], allow=PUBLIC)
    def brand_new(principal):
        return {}

    app.register_blueprint(bp)
    message = table_mismatch(app, {("GET", "/api/listed"): None, ("GET", "/api/gone"): None})

    assert "without an entry (add who may call them): [('POST', '/api/brand-new')]" in message
    assert "do not exist (remove them): [('GET', '/api/gone')]" in message


def test_every_entry_names_an_outcome_for_each_principal():
    for key, case in TABLE.items():
        assert set(case.expect) == set(PRINCIPALS), key
        assert set(case.expect.values()) <= {"allow", "deny", "deny404"}, key


def test_the_principals_are_who_they_claim_to_be(world: World):
    for name, groups in {"racer_a": ["racer"], "operator": ["operator"], "admin": ["admin"]}.items():
        me = world.ok("GET", "/api/me", name)
        assert (me["username"], me["roles"]) == (world.usernames[name], groups)
    for device, kind in (("car_x", "car"), ("car_y", "car"), ("timer", "timer")):
        me = world.ok("GET", "/api/devices/self", device)
        assert (me["device_id"], me["kind"]) == (world.device_ids[device], kind)
    cookie_me = world.call("GET", "/api/me", "admin_cookie")
    assert cookie_me.status == 200 and cookie_me.json["roles"] == ["admin"] and "drem_session" in \
        world.headers["admin_cookie"]["Cookie"] and "Authorization" not in world.headers["admin_cookie"]
    assert world.call("GET", "/api/me", "anonymous").status == 401


@pytest.mark.parametrize("principal", PRINCIPALS)
@pytest.mark.parametrize(("method", "path"), sorted(TABLE), ids=[f"{m} {p}" for m, p in sorted(TABLE)])
def test_authz_matrix(world: World, method: str, path: str, principal: str):
    case = TABLE[(method, path)]
    expected = case.expect[principal]
    call = scenario_for(world, (method, path), principal)
    caller = world.mint(principal) if case.consumes_caller and expected == "allow" else principal
    body = call.body if call.body is not None else ({} if method in {"POST", "PUT", "PATCH"} else None)

    reply = world.call(method, concrete_path(path, call.params), caller, body, call.headers, call.raw)

    denied = reply.status in DENIED.get(expected, {401, 403})
    assert denied == (expected != "allow") and reply.status < 500, (
        f"{method} {path} as {principal}: expected {expected}, got {reply.status} {reply.body[:300]!r}")


def test_the_cookie_path_without_the_csrf_token_is_refused(world: World):
    # The same admin session, minus the header: every state-changing route must refuse it (403), none may act.
    headers = {"X-CSRF-Token": ""}
    for (method, path), case in sorted(TABLE.items()):
        if method == "GET" or case.expect["admin_cookie"] != "allow" or case.expect["anonymous"] == "allow":
            continue  # public routes: nothing of the admin's to abuse (CSRF-exempt ones act as anonymous)
        reply = world.call(method, concrete_path(path, {}), "admin_cookie", {},
                           headers={**headers, "Content-Type": case.content_type})
        assert reply.status == 403, f"{method} {path} acted without a CSRF token: {reply.status}"
