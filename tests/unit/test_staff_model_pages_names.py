"""Issue 31: the staff model registry and the learning booth's "every racer" page named racers by sign-in name in
their Racer columns. Now by display name, "Björn (bjorn_a)" where two racers the page lists are both Björn (HTTP, the
Chalice test client over moto: what the page shows)."""
from __future__ import annotations

import json
import re
from typing import Any

import pytest

from tests.unit.models_helpers import ModelsApi, bearer, onnx_archive
from tests.unit.test_booth_api import drive

pytestmark = pytest.mark.unit

RACERS = (("bjorn_a", "Björn"), ("bjorn_b", "björn"), ("yamada", "山田太郎"))


def _named_racer(client: Any, users: Any, username: str, display_name: str) -> ModelsApi:
    token = users.access_token(username, ("racer",))
    named = client.http.put("/api/me/profile", body=json.dumps({"display_name": display_name}),
                            headers={**bearer(token), "Content-Type": "application/json"})
    assert named.status_code == 200, named.body
    return ModelsApi(client, bearer(token))


def _column(html: str, testid: str) -> list[str]:
    return sorted(re.findall(rf'data-testid="{testid}">([^<]*)</td>', html))


def test_the_staff_registry_and_booth_name_racers_by_display_name(client: Any, users: Any) -> None:
    for bias, (username, name) in enumerate(RACERS):
        racer = _named_racer(client, users, username, name)
        assert racer.upload_and_complete(f"{username}-v1.tar.gz", onnx_archive(0.1 * bias))["status"] == "AVAILABLE"
        drive(racer, steps=5)
    staff = {"Authorization": bearer(users.access_token("olga", ("operator",)))["Authorization"]}

    registry = client.http.get("/console/models/registry", headers=staff)
    assert registry.status_code == 200
    assert _column(registry.body.decode(), "registry-racer") == ["Björn (bjorn_a)", "björn (bjorn_b)", "山田太郎"]

    booth = client.http.get("/booth?everyone=true", headers=staff)
    assert booth.status_code == 200
    assert _column(booth.body.decode(), "run-racer") == ["Björn (bjorn_a)", "björn (bjorn_b)", "山田太郎"]


def _racer_spans(html: str, testid: str) -> list[str]:
    return sorted(re.findall(rf'data-testid="{testid}">([^<]*)</', html))


def test_the_booth_jobs_a_run_and_a_models_detail_name_the_racer_by_display_name(client: Any, users: Any) -> None:
    """Issue 31: staff's training-jobs list (the booth page and the fragment it polls every second), a run's page
    header and a registry model's heading named the racer by sign-in name. Now by display name, told apart in the jobs
    list alike on the page and in its poll; a page about one racer's run or model shows the plain display name."""
    queued: dict[str, dict[str, Any]] = {}
    for bias, (username, name) in enumerate(RACERS):
        racer = _named_racer(client, users, username, name)
        racer.upload_and_complete(f"{username}-v1.tar.gz", onnx_archive(0.1 * bias))
        run = drive(racer, steps=5)
        job = racer.call("POST", "/api/training-jobs", {"run_ids": [run["run_id"]]})
        assert job.status_code == 201, job.json_body
        queued[username] = {"run": run, "racer": racer}
    staff = {"Authorization": bearer(users.access_token("olga", ("operator",)))["Authorization"]}

    told_apart = ["Björn (bjorn_a)", "björn (bjorn_b)", "山田太郎"]
    booth = client.http.get("/booth?everyone=true", headers=staff).body.decode()
    assert _racer_spans(booth, "job-racer") == told_apart
    polled = client.http.get("/booth/jobs?everyone=true", headers=staff).body.decode()
    assert 'hx-trigger="every 1s"' in polled and _racer_spans(polled, "job-racer") == told_apart

    run_page = client.http.get(f"/booth/runs/{queued['bjorn_a']['run']['run_id']}", headers=staff).body.decode()
    assert _racer_spans(run_page, "run-owner") == ["Björn"]
    yamada = queued["yamada"]["racer"]
    model_id = yamada.call("GET", "/api/models").json_body["models"][0]["model_id"]
    detail = client.http.get(f"/models/registry/{model_id}", headers=staff).body.decode()
    assert _racer_spans(detail, "registry-model-racer") == ["(山田太郎)"]
