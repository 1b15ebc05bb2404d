"""Model upload over real HTTP: the app serves the API and forwards the presigned POST to the durable moto server."""
from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

import pytest
import requests

from drem_local.api_client import ApiClient, ApiError
from tests.unit.models_helpers import archive_without_metadata, onnx_archive, onnx_policy

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def admin_api(live_stack) -> ApiClient:
    api = ApiClient(live_stack.url)
    api.token = api.sign_in(live_stack.admin_username, live_stack.admin_password)
    return api


def upload(api: ApiClient, filename: str, data: bytes) -> dict:
    ticket = api.post("/api/models", {"filename": filename})
    # Locally the browser posts to the app's own storage gateway (same origin), never to the storage port.
    assert ticket["upload"]["url"].startswith(api.base_url + "/_storage/"), ticket["upload"]["url"]
    posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"],
                           files={"file": (filename, data)}, timeout=30)
    assert posted.status_code in (200, 204), posted.text
    return api.post(f"/api/models/{ticket['model']['model_id']}/complete")["model"]


def test_presigned_post_then_complete_makes_the_model_available(admin_api: ApiClient) -> None:
    archive = onnx_archive(0.125)
    model = upload(admin_api, "http_model.tar.gz", archive)

    assert model["status"] == "AVAILABLE"
    assert model["model_md5"] == hashlib.md5(onnx_policy(0.125)).hexdigest()
    assert model["archive_md5"] == hashlib.md5(archive).hexdigest()
    listed = admin_api.get("/api/models")["models"]
    assert model["model_id"] in [m["model_id"] for m in listed]
    again = admin_api.post(f"/api/models/{model['model_id']}/complete")["model"]
    # Completing twice changes nothing of the upload; the background test drive moves on by itself meanwhile.
    driving = {"scrutineer_status", "scrutineer_state", "updated_at"}
    assert {k: v for k, v in again.items() if k not in driving} == {k: v for k, v in model.items() if k not in driving}


def test_an_invalid_archive_is_not_valid_with_a_reason(admin_api: ApiClient) -> None:
    model = upload(admin_api, "no_metadata.tar.gz", archive_without_metadata())
    assert model["status"] == "NOT_VALID"
    assert "model_metadata.json" in model["reason"]


def test_cli_upload_prints_the_verdict(live_stack, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from drem_local.commands import models as command

    archive = tmp_path / "cli_model.tar.gz"
    archive.write_bytes(onnx_archive(0.375))
    parser = argparse.ArgumentParser()
    command.add_arguments(parser)
    args = parser.parse_args(["--api", live_stack.url, "--username", live_stack.admin_username,
                              "--password", live_stack.admin_password, "upload", str(archive)])
    assert command.run(args) == 0
    printed = capsys.readouterr().out
    assert "cli_model" in printed and "Ready to race" in printed  # the label, not the enum value


def test_wrong_password_is_refused(live_stack) -> None:
    with pytest.raises(ApiError):
        ApiClient(live_stack.url).sign_in(live_stack.admin_username, "Not-the-password-1")


def test_the_storage_server_enforces_the_ticket_the_app_signed(admin_api: ApiClient) -> None:
    """moto alone ignores the presigned POST's policy; the durable server in front of it does not."""
    ticket = admin_api.post("/api/models", {"filename": "ticket_abuse.tar.gz"})
    upload = ticket["upload"]
    other_key = upload["fields"]["key"].replace(ticket["model"]["model_id"], "someone-elses-model")

    wrong_key = requests.post(upload["url"], data={**upload["fields"], "key": other_key},
                              files={"file": ("x.tar.gz", onnx_archive(0.5))}, timeout=30)
    empty = requests.post(upload["url"], data=upload["fields"], files={"file": ("x.tar.gz", b"")}, timeout=30)

    assert wrong_key.status_code == 403 and "<Code>AccessDenied</Code>" in wrong_key.text
    assert empty.status_code == 400 and "<Code>EntityTooSmall</Code>" in empty.text
    with pytest.raises(ApiError) as not_arrived:  # nothing reached the ticket's own key either
        admin_api.post(f"/api/models/{ticket['model']['model_id']}/complete")
    assert "has not arrived yet" in str(not_arrived.value)
    good = requests.post(upload["url"], data=upload["fields"], files={"file": ("x.tar.gz", onnx_archive(0.5))},
                         timeout=30)
    assert good.status_code in (200, 204), good.text
    assert admin_api.post(f"/api/models/{ticket['model']['model_id']}/complete")["model"]["status"] == "AVAILABLE"


def test_a_query_on_the_ticket_url_does_not_switch_the_policy_off(admin_api: ApiClient, live_stack) -> None:
    """Issue 27, as reported: a racer's own ticket from POST /api/models, posted to `{url}?x=1` with another
    racer's archive key, to `{url}?delete` with a <Delete> document, with 0 bytes or a redirect to another site."""
    bucket = live_stack.outputs.buckets["models"]
    storage = live_stack.client("s3")
    victim_key = "models/victim-sub/victim-model.tar.gz"
    storage.put_object(Bucket=bucket, Key=victim_key, Body=b"the victim's validated archive")
    ticket = admin_api.post("/api/models", {"filename": "query_abuse.tar.gz"})
    url, fields = ticket["upload"]["url"], ticket["upload"]["fields"]
    delete_doc = f"<Delete><Object><Key>{victim_key}</Key></Object></Delete>".encode()

    attempts = {
        "other key via ?x=1": requests.post(f"{url}?x=1", data={**fields, "key": victim_key},
                                            files={"file": ("x.tar.gz", b"overwritten")}, timeout=30),
        "?delete": requests.post(f"{url}?delete", data=fields, files={"file": ("d.xml", delete_doc)}, timeout=30),
        "0 bytes via ?x=1": requests.post(f"{url}?x=1", data=fields, files={"file": ("x.tar.gz", b"")}, timeout=30),
        "redirect": requests.post(f"{url}?x=1", data={**fields, "success_action_redirect": "https://evil.example/"},
                                  files={"file": ("x.tar.gz", b"x")}, timeout=30, allow_redirects=False),
    }

    for what, reply in attempts.items():
        assert reply.status_code in (400, 403), (what, reply.status_code, reply.text)
        assert "Location" not in reply.headers, what
    assert storage.get_object(Bucket=bucket, Key=victim_key)["Body"].read() == b"the victim's validated archive"
    with pytest.raises(ApiError) as not_arrived:
        admin_api.post(f"/api/models/{ticket['model']['model_id']}/complete")
    assert "has not arrived yet" in str(not_arrived.value)
