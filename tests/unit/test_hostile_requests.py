"""Requests an attacker would type by hand: numbers Python refuses to read, page tokens we never issued, JSON nested
thousands deep. Each once ended in a 500 (or a 502 blaming Cognito); each must be a 400 that names the field, while
the ordinary request beside it still works."""
from __future__ import annotations

import json
from typing import Any

import pytest

from tests.unit.race_helpers import Desk
from tests.unit.scenario import Scenario
from tests.unit.test_registry import DREM_METADATA, onnx_policy, tar_gz
from tests.unit.users_helpers import call

pytestmark = pytest.mark.unit

PAST_PYTHONS_INT_LIMIT = "9" * 4_301  # int() refuses more than 4,300 digits (sys.get_int_max_str_digits)


def _field(reply: Any) -> str | None:
    return json.loads(reply.body)["error"].get("field")


@pytest.fixture
def race_with_a_lap(scenario: Scenario) -> tuple[str, str]:
    scenario.add_racers("lea").add_event().add_race("lea", laps=[12_000])
    return scenario.event_id, scenario.race_id


@pytest.mark.parametrize("lap_id", [PAST_PYTHONS_INT_LIMIT, "²", "٣", "-1", "0x1", "1e3", "10000"])
def test_lap_ids_python_cannot_read_are_a_400(desk: Desk, race_with_a_lap, lap_id: str) -> None:
    eid, rid = race_with_a_lap

    reply = desk.call("PUT", f"/api/events/{eid}/races/{rid}/laps/{lap_id}", {"is_valid": False})

    assert reply.status_code == 400, reply.body
    assert _field(reply) == "lap_id"
    assert desk.ok(desk.call("PUT", f"/api/events/{eid}/races/{rid}/laps/0", {"is_valid": False}))


@pytest.mark.parametrize("limit", ["²", PAST_PYTHONS_INT_LIMIT, "0", "61", " ", "1.5"])
def test_user_listing_limit_that_is_not_a_small_whole_number_is_a_400(client, users, limit: str) -> None:
    admin = users.access_token("boss", ("admin",))

    status, body = call(client, "GET", f"/api/users?limit={limit}", token=admin)

    assert status == 400, body
    assert body["error"]["field"] == "limit" and "between 1 and 60" in body["error"]["message"]
    assert call(client, "GET", "/api/users?limit=60", token=admin)[0] == 200


def test_a_page_token_cognito_never_issued_is_a_400_not_a_502(client, users) -> None:
    admin = users.access_token("boss", ("admin",))
    for name in ("p1", "p2", "p3"):
        users.create(name, ("racer",))

    status, body = call(client, "GET", "/api/users?limit=2&next=garbage", token=admin)

    assert status == 400, body
    assert body["error"]["field"] == "next" and "start again from the first page" in body["error"]["message"]
    status, first = call(client, "GET", "/api/users?limit=2", token=admin)
    assert status == 200 and first["next_token"]
    assert call(client, "GET", f"/api/users?limit=2&next={first['next_token']}", token=admin)[0] == 200


def test_lineage_nested_thousands_deep_is_a_note_not_a_500(alice, client) -> None:
    deep = b"[" * 100_000 + b"]" * 100_000  # gzip makes it tiny; json.loads recursed until RecursionError
    model = alice.upload_and_complete("deep.tar.gz", tar_gz([
        ("model.onnx", onnx_policy(0.3)), ("model_metadata.json", json.dumps(DREM_METADATA).encode()),
        ("training/lineage.json", deep)]))
    assert model["status"] == "AVAILABLE"

    detail = client.http.get(f"/models/registry/{model['model_id']}",
                             headers={"Authorization": alice.headers["Authorization"]})

    assert detail.status_code == 200
    assert "training/lineage.json could not be read" in detail.body.decode()
    assert "nested too deeply" in detail.body.decode()
