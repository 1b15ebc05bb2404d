"""/healthz, static files, the request log line and the error→HTTP mapping."""
from __future__ import annotations

import io
import json
import logging
import socket

import pytest
from pydantic import BaseModel, ValidationError

from tests.unit.conftest import bearer

pytestmark = pytest.mark.unit


def test_healthz_tells_anyone_only_whether_it_is_up(client, stack):
    response = client.http.get("/healthz")

    assert response.status_code == 200
    assert response.json_body == {"status": "ok"}


@pytest.mark.parametrize("role", ["racer", "anonymous visitor"])
def test_healthz_hides_storage_and_versions_from_non_staff(client, users, role):
    headers = bearer(users.access_token("rita", ("racer",))) if role == "racer" else {}

    body = client.http.get("/healthz", headers=headers).json_body

    assert body == {"status": "ok"}


def test_healthz_reports_storage_region_and_stage_to_staff(client, users):
    response = client.http.get("/healthz", headers=bearer(users.access_token("ops", ("operator",))))

    assert response.status_code == 200
    assert response.json_body == {"status": "ok", "storage": "aws", "region": "us-east-1", "stage": "test",
                                  "tables": "ok", "state_dir": None}


def test_healthz_is_503_when_the_tables_are_missing(client, stack, users, aws_clients):
    admin = bearer(users.access_token("ada", ("admin",)))
    aws_clients.dynamodb.delete_table(TableName=stack.tables["events"])

    response = client.http.get("/healthz", headers=admin)

    assert response.status_code == 503
    assert response.json_body["tables"] == "missing"
    assert client.http.get("/healthz").json_body == {"status": "degraded"}


def test_healthz_is_503_when_the_local_endpoint_is_down(client, stack, monkeypatch):
    # Staff cannot be verified while storage is down (their tokens' revocation marks live there): `drem status`
    # reports the storage side then; the public answer still says the app is unavailable.
    from chalicelib.settings import get_settings
    from chalicelib.storage.clients import reset_clients

    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        dead = f"http://127.0.0.1:{probe.getsockname()[1]}"
    monkeypatch.setenv("AWS_ENDPOINT_URL", dead)
    get_settings.cache_clear()
    reset_clients()

    response = client.http.get("/healthz")

    assert response.status_code == 503
    assert response.json_body == {"status": "unavailable"}


def test_healthz_details_name_an_unreachable_state_dir():
    from chalicelib.domain.health import check_health

    report = check_health(storage_label="http://127.0.0.1:1", region="us-east-1", stage="local",
                          probe_table=lambda: "unreachable", durable_health=lambda: "unreachable")

    assert (report.status, report.tables, report.state_dir) == ("unavailable", "unreachable", "unreachable")


def test_htmx_is_served_with_its_mimetype_and_caching(client, stack, repo_root):
    vendored = repo_root / "web/drem_web/static/vendor/htmx.min.js"
    if not vendored.is_file():
        pytest.fail("htmx is not installed: run `make install` (copies it from node_modules)")

    response = client.http.get("/static/vendor/htmx.min.js")

    assert response.status_code == 200
    assert response.headers["Content-Type"].startswith("text/javascript")
    assert "max-age=" in response.headers["Cache-Control"]
    assert response.body == vendored.read_bytes()


@pytest.mark.parametrize("name", ["..%2F..%2Fapp.py", "..", ".hidden", "nope.css", "%2Fetc%2Fpasswd"])
def test_static_rejects_traversal_and_unknown_files(client, stack, name):
    assert client.http.get(f"/static/{name}").status_code == 404


def test_each_request_logs_one_json_line_with_its_request_id(client, users):
    token = users.access_token("lou", ("racer",))
    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    from chalicelib.logs import JsonFormatter

    handler.setFormatter(JsonFormatter())
    logger = logging.getLogger("drem.json")
    logger.addHandler(handler)
    try:
        response = client.http.get("/api/me", headers=bearer(token))
    finally:
        logger.removeHandler(handler)

    lines = [json.loads(line) for line in stream.getvalue().splitlines()]
    requests = [line for line in lines if line["msg"] == "request"]
    assert len(requests) == 1
    line = requests[0]
    assert line["request_id"] == response.headers["X-Request-Id"]
    assert (line["method"], line["path"], line["status"]) == ("GET", "/api/me", 200)
    assert line["principal"] == f"user:{response.json_body['sub']}"
    assert line["duration_ms"] >= 0


class _Entry(BaseModel):
    lap_ms: int
    racer: str


def test_validation_errors_name_the_field():
    from chalicelib.http_errors import to_response

    with pytest.raises(ValidationError) as caught:
        _Entry.model_validate({"lap_ms": "fast"})
    response = to_response(caught.value, None)

    body = json.loads(response.to_dict()["body"])["error"]
    assert response.status_code == 400
    assert set(body["fields"]) == {"lap_ms", "racer"}
    assert "lap_ms:" in body["message"] and "racer:" in body["message"]


def test_unexpected_errors_are_500_without_details():
    from chalicelib.http_errors import to_response

    response = to_response(RuntimeError("secret internals"), None)

    body = json.loads(response.to_dict()["body"])["error"]
    assert response.status_code == 500
    assert "secret" not in body["message"]
