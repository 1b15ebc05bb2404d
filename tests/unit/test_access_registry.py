"""Every route declares who may call it; the declarations are data a matrix test can read."""
from __future__ import annotations

import pytest
from chalice import Blueprint, Chalice

from chalicelib.auth.access import (
    ADMIN,
    CAR,
    PUBLIC,
    SIGNED_IN,
    TIMER,
    Allow,
    declared_routes,
    route,
    undeclared_routes,
)
from chalicelib.core.principals import ANONYMOUS, Device, User

pytestmark = pytest.mark.unit


def test_every_app_route_is_declared_through_the_access_wrapper(chalice_app):
    assert undeclared_routes(chalice_app) == []
    declared = {(r.path, r.method): r.allow for r in declared_routes(chalice_app)}
    assert declared[("/api/me", "GET")] == SIGNED_IN
    assert declared[("/api/users/{username}/groups", "GET")] == Allow(roles=frozenset({ADMIN}))
    assert declared[("/healthz", "GET")] == PUBLIC


def test_a_route_registered_without_the_wrapper_is_reported():
    app = Chalice(app_name="registry-check")
    bp = Blueprint(__name__)

    @route(bp, "/declared", allow=PUBLIC)
    def declared(principal):
        return {}

    @bp.route("/sneaky")
    def sneaky():
        return {}

    app.register_blueprint(bp)

    assert undeclared_routes(app) == [("/sneaky", "GET")]
    assert [(r.path, r.method) for r in declared_routes(app)] == [("/declared", "GET")]


def test_allow_sets_must_name_a_role():
    with pytest.raises(ValueError):
        route(Blueprint(__name__), "/nobody", allow=set())


ALICE_RACER = User(sub="a", username="alice", groups=frozenset({"racer"}))
OLGA_OPERATOR = User(sub="o", username="olga", groups=frozenset({"operator"}))
ADA_ADMIN = User(sub="d", username="ada", groups=frozenset({"admin", "made-up-group"}))
CAR_1 = Device(device_id="car-1", device_kind="car")

# (allow, principal, expected): None = allowed, else the HTTP status the wrapper will answer
DECISIONS = [
    (PUBLIC, ANONYMOUS, None), (PUBLIC, CAR_1, None),
    (SIGNED_IN, ANONYMOUS, 401), (SIGNED_IN, ALICE_RACER, None), (SIGNED_IN, CAR_1, 403),
    ({ADMIN}, ANONYMOUS, 401), ({ADMIN}, ALICE_RACER, 403), ({ADMIN}, OLGA_OPERATOR, 403), ({ADMIN}, ADA_ADMIN, None),
    ({CAR, TIMER}, CAR_1, None), ({CAR, TIMER}, ADA_ADMIN, 403), ({TIMER}, CAR_1, 403),
]


@pytest.mark.parametrize(("allow", "principal", "expected"), DECISIONS)
def test_allow_decisions(allow, principal, expected):
    from chalicelib.auth.access import as_allow
    from chalicelib.http_errors import status_for

    try:
        as_allow(allow).decide(principal)
        outcome = None
    except Exception as exc:  # noqa: BLE001 - the status the wrapper would map it to is what matters
        outcome = status_for(exc)

    assert outcome == expected


def test_browser_get_of_a_signed_in_page_redirects_to_login(stack, tmp_path):
    from chalice.test import Client

    from drem_web import render

    app = Chalice(app_name="redirect-check")
    bp = Blueprint(__name__)

    @route(bp, "/my/page", allow=SIGNED_IN)
    def my_page(principal):
        return render.page("home", roles=[], links=[])

    app.register_blueprint(bp)
    with Client(app, project_dir=str(tmp_path)) as client:
        page = client.http.get("/my/page", headers={"Accept": "text/html"})
        api = client.http.get("/my/page", headers={"Accept": "application/json"})

    assert page.status_code == 303 and page.headers["Location"] == "/login?next=/my/page"
    assert api.status_code == 401


def test_signed_in_browser_without_the_role_gets_the_403_page(users, tmp_path):
    from chalice.test import Client

    from chalicelib.auth.access import OPERATOR
    from drem_web import render

    token = users.access_token("rita", ("racer",))
    app = Chalice(app_name="forbidden-check")
    bp = Blueprint(__name__)

    @route(bp, "/operator/desk", allow={ADMIN, OPERATOR})
    def desk(principal):
        return render.page("home", roles=[], links=[])

    app.register_blueprint(bp)
    with Client(app, project_dir=str(tmp_path)) as client:
        response = client.http.get("/operator/desk", headers={"Accept": "text/html",
                                                              "Cookie": f"drem_session={token}"})

    html = response.body.decode()
    assert response.status_code == 403
    assert response.headers["Content-Type"].startswith("text/html")
    assert "This needs the role admin or operator." in html
    assert "You are signed in as <strong>rita</strong>" in html
