"""The OpenAPI document is generated from the route declarations, is valid OpenAPI 3.1, and is served; routes that
declare `body=`/`query=` get their input validated by the wrapper."""
from __future__ import annotations

import json

import pytest
from chalice import Blueprint, Chalice
from chalice.test import Client
from openapi_spec_validator import validate
from pydantic import BaseModel, Field

from chalicelib.auth.access import ADMIN, CAR, OPERATOR, PUBLIC, SIGNED_IN, declared_routes, route
from chalicelib.openapi import allow_label, build_document, operation_rows
from tests.unit.authz_principals import full_app
from tests.unit.conftest import bearer

pytestmark = pytest.mark.unit


class LapTime(BaseModel):
    lap_ms: int = Field(gt=0, description="the lap's time in milliseconds")
    valid: bool = True


class NewRace(BaseModel):
    racer: str = Field(min_length=1, description="who drives")
    laps: list[LapTime] = []
    note: str | None = None


class Race(BaseModel):
    race_id: str
    racer: str


class Paging(BaseModel):
    limit: int = Field(default=20, ge=1, le=100, description="how many per page")
    track: str | None = None


def small_app() -> Chalice:
    app, bp = Chalice(app_name="openapi-check"), Blueprint(__name__)

    @route(bp, "/api/events/{event_id}/races", methods=["POST"], allow={ADMIN, OPERATOR}, body=NewRace,
           response=Race, status_code=201, tags=("races",))
    def add_race(principal, event_id: str, body: NewRace):
        """Add a race to an event.

        The racer must be registered."""
        return {"race_id": "r1", "racer": body.racer, "laps": len(body.laps), "event_id": event_id}

    @route(bp, "/api/events/{event_id}/races", allow=SIGNED_IN, query=Paging, response=list[Race])
    def list_races(principal, event_id: str, query: Paging):
        return {"limit": query.limit, "track": query.track}

    @route(bp, "/api/boards/{event_id}", allow=PUBLIC, conditional=True)
    def board(principal, event_id: str):
        return {}

    @route(bp, "/api/cars/self/ping", methods=["POST"], allow={CAR})
    def ping(principal):
        return {}

    @route(bp, "/dashboard", allow=SIGNED_IN)
    def dashboard(principal):
        return {}

    app.register_blueprint(bp)
    return app


def component(document: dict, ref: str) -> dict:
    return document["components"]["schemas"][ref.rsplit("/", 1)[-1]]


def test_the_whole_app_document_is_valid_and_lists_every_api_route_with_who_may_call_it(chalice_app):
    app = full_app(chalice_app)
    document = build_document(app)

    validate(document)
    api_routes = [r for r in declared_routes(app) if r.path.startswith("/api/") or r.path == "/healthz"]
    assert ("/api/me", "GET") in {(r.path, r.method) for r in api_routes}
    for declared in api_routes:
        operation = document["paths"][declared.path][declared.method.lower()]
        assert operation["x-drem-allow"] == allow_label(declared.allow), (declared.path, declared.method)
        assert (operation["security"] == []) == declared.allow.public
    assert sum(len([m for m in ops if m != "parameters"]) for ops in document["paths"].values()) == len(api_routes)
    assert "/" not in document["paths"] and "/login" not in document["paths"]
    assert document["paths"]["/api/me"]["get"]["x-drem-allow"] == "signed in"
    assert document["paths"]["/healthz"]["get"]["security"] == []
    assert {"deviceAuth": []} in document["paths"]["/api/devices/self"]["get"]["security"]
    assert document["paths"]["/api/users/{username}/groups"]["get"]["x-drem-allow"] == ["admin"]
    # A write may meet a full disk: the document says the client can get 507 there, and only there.
    assert document["paths"]["/api/users"]["post"]["responses"]["507"] == {"$ref": "#/components/responses/507"}
    assert "full" in document["components"]["responses"]["507"]["description"]
    assert "507" in document["paths"]["/api/events/{event_id}"]["delete"]["responses"]
    assert "507" not in document["paths"]["/api/me"]["get"]["responses"]


def test_a_route_with_body_shows_its_schema_with_required_fields():
    document = build_document(small_app())
    validate(document)

    operation = document["paths"]["/api/events/{event_id}/races"]["post"]
    body = component(document, operation["requestBody"]["content"]["application/json"]["schema"]["$ref"])
    assert body["required"] == ["racer"]
    assert body["properties"]["racer"]["description"] == "who drives"
    lap = component(document, body["properties"]["laps"]["items"]["$ref"])  # $defs hoisted into components
    assert lap["required"] == ["lap_ms"]
    assert operation["summary"] == "Add a race to an event."
    assert operation["description"] == "The racer must be registered."
    assert operation["tags"] == ["races"] and operation["x-drem-allow"] == ["admin", "operator"]
    created = operation["responses"]["201"]["content"]["application/json"]["schema"]
    assert component(document, created["$ref"])["required"] == ["race_id", "racer"]
    assert operation["responses"]["403"] == {"$ref": "#/components/responses/403"}
    assert document["paths"]["/api/events/{event_id}/races"]["parameters"][0]["name"] == "event_id"


def test_query_list_responses_conditional_gets_devices_and_undocumented_routes():
    document = build_document(small_app())
    listing = document["paths"]["/api/events/{event_id}/races"]["get"]
    board = document["paths"]["/api/boards/{event_id}"]["get"]
    ping = document["paths"]["/api/cars/self/ping"]["post"]

    assert {p["name"]: p["required"] for p in listing["parameters"]} == {"limit": False, "track": False}
    assert listing["responses"]["200"]["content"]["application/json"]["schema"]["type"] == "array"
    assert listing["summary"] == "List races" and listing["x-drem-allow"] == "signed in"
    assert "304" in board["responses"] and "304" not in listing["responses"]
    assert board["security"] == [] and board["x-drem-allow"] == "public"
    # declared without any documentation keywords: still there, with the shared error answers
    assert ping["security"] == [{"deviceAuth": []}] and ping["x-drem-allow"] == ["car"]
    assert set(ping["responses"]) == {"200", "400", "401", "403", "404", "409", "507"}  # a POST writes
    assert "/dashboard" not in document["paths"]


def test_declared_body_and_query_are_validated_after_the_caller_is_checked(users, tmp_path):
    token = users.access_token("olga", ("operator",))
    with Client(small_app(), project_dir=str(tmp_path)) as client:
        def post(body: object, headers: dict) -> tuple[int, dict]:
            reply = client.http.post("/api/events/e1/races", body=json.dumps(body).encode(),
                                     headers={**headers, "Content-Type": "application/json"})
            return reply.status_code, json.loads(reply.body)

        anonymous = post({}, {"Accept": "application/json"})
        missing = post({"laps": [{"lap_ms": 9000}]}, bearer(token))
        bad_lap = post({"racer": "rita", "laps": [{"lap_ms": -1}]}, bearer(token))
        good = post({"racer": "rita", "laps": [{"lap_ms": 9000}]}, bearer(token))
        listed = client.http.get("/api/events/e1/races?limit=5&track=2", headers=bearer(token))
        bad_query = client.http.get("/api/events/e1/races?limit=0", headers=bearer(token))

    assert anonymous[0] == 401
    assert missing[0] == 400 and missing[1]["error"]["field"] == "racer"
    assert bad_lap[0] == 400 and bad_lap[1]["error"]["field"] == "laps.0.lap_ms"
    assert good == (200, {"race_id": "r1", "racer": "rita", "laps": 1, "event_id": "e1"})
    assert json.loads(listed.body) == {"limit": 5, "track": "2"}
    assert bad_query.status_code == 400 and json.loads(bad_query.body)["error"]["field"] == "limit"


def test_the_document_and_the_docs_page_are_served_to_anyone(stack, chalice_app, tmp_path):
    with Client(full_app(chalice_app), project_dir=str(tmp_path)) as client:
        served = client.http.get("/api/openapi.json")
        page = client.http.get("/api/docs", headers={"Accept": "text/html"})

    document = json.loads(served.body)
    validate(document)
    assert served.status_code == 200 and document["paths"]["/api/openapi.json"]["get"]["security"] == []
    html = page.body.decode()
    assert page.status_code == 200 and page.headers["Content-Type"].startswith("text/html")
    assert 'data-method="DELETE" data-path="/api/devices/{device_id}"' in html
    assert html.count('data-testid="api-operation"') == len(operation_rows(document))
    layout_scripts = ('<script src="/static/urls.js" defer></script>',
                      '<script src="/static/vendor/htmx.min.js" defer></script>',
                      '<script src="/static/drem.js" defer></script>')
    for script in layout_scripts:
        html = html.replace(script, "")
    assert "<script" not in html


def test_the_docs_page_lists_body_fields():
    from drem_web import render

    rows = operation_rows(build_document(small_app()))
    html = render.render_page("api_docs", operations=rows)

    add_race = next(r for r in rows if r["method"] == "POST" and r["path"] == "/api/events/{event_id}/races")
    assert [(f["name"], f["required"]) for f in add_race["body_fields"]] == [
        ("racer", True), ("laps", False), ("note", False)]
    assert add_race["allow"] == "admin, operator"
    assert "<code>racer</code> string <strong>required</strong> — who drives" in html
    assert "<code>limit</code>" in html


REQUEST_BODIES = {  # a representative write of every area → a field its request schema must list as required
    ("post", "/api/events"): "name",
    ("post", "/api/fleets"): "name",
    ("post", "/api/devices/activation-codes"): "fleet_id",
    ("post", "/api/devices/activate"): "code",
    ("post", "/api/devices/self/heartbeat"): None,
    ("post", "/api/models"): "filename",
    ("put", "/api/cars/{device_id}/models"): "model_ids",
    ("post", "/api/events/{event_id}/races"): "track_id",
    ("post", "/api/events/{event_id}/races/{race_id}/commands"): None,
    ("post", "/api/timing/strip-events"): "event_id",
    ("post", "/api/signup"): "username",
    ("post", "/api/users"): "username",
    ("put", "/api/me/profile"): None,
    ("post", "/api/auth/token"): "password",
    ("post", "/api/auth/refresh"): "refresh_token",
}


def request_schema(document: dict, method: str, path: str) -> dict:
    operation = document["paths"][path][method]
    schema = operation["requestBody"]["content"]["application/json"]["schema"]
    return component(document, schema["$ref"]) if "$ref" in schema else schema


def test_the_served_document_has_request_schemas_for_every_area_and_304_on_the_polls(stack, chalice_app, tmp_path):
    with Client(full_app(chalice_app), project_dir=str(tmp_path)) as client:
        document = json.loads(client.http.get("/api/openapi.json").body)

    for (method, path), required in REQUEST_BODIES.items():
        schema = request_schema(document, method, path)
        assert schema.get("properties") or schema.get("oneOf") or schema.get("anyOf"), (method, path, schema)
        if required is not None:
            assert required in schema.get("required", []), (method, path, schema.get("required"))
    command = request_schema(document, "post", "/api/events/{event_id}/races/{race_id}/commands")
    kinds = {component(document, option["$ref"])["properties"]["kind"].get("const")
             for option in command.get("oneOf", command.get("anyOf", []))}
    assert {"start", "capture_lap", "end"} <= kinds
    for path in ("/api/leaderboard/{event_id}", "/api/overlay/{event_id}"):
        assert "304" in document["paths"][path]["get"]["responses"], path
    assert "304" not in document["paths"]["/api/events/{event_id}"]["get"]["responses"]
    for created in (("post", "/api/events"), ("post", "/api/fleets"), ("post", "/api/models"), ("post", "/api/users")):
        assert "201" in document["paths"][created[1]][created[0]]["responses"], created
    assert {p["name"] for p in document["paths"]["/api/models"]["get"]["parameters"]} >= {"limit"}
    grant = document["paths"]["/api/auth/refresh"]["post"]["responses"]["200"]["content"]["application/json"]
    assert component(document, grant["schema"]["$ref"])["properties"]["token_type"]["const"] == "Bearer"
    assert document["paths"]["/api/auth/token"]["post"]["security"] == []
