"""Model upload, validation, listing and soft delete through the JSON API (in-process moto, real presigned POSTs)."""
from __future__ import annotations

import base64
import gzip
import hashlib
import io
import json
import tarfile
from typing import Any

import pytest
from chalice.test import Client

from tests.unit.models_helpers import (
    ModelsApi,
    archive_without_metadata,
    bearer,
    onnx_archive,
    onnx_policy,
    traversal_archive,
)

pytestmark = pytest.mark.unit


@pytest.fixture
def app_client(client: Client) -> Client:
    return client


@pytest.fixture
def racer_a(app_client: Client, users: Any) -> ModelsApi:
    return ModelsApi(app_client, bearer(users.access_token("alice", ("racer",))))


@pytest.fixture
def racer_b(app_client: Client, users: Any) -> ModelsApi:
    return ModelsApi(app_client, bearer(users.access_token("bob", ("racer",))))


@pytest.fixture
def operator(app_client: Client, users: Any) -> ModelsApi:
    return ModelsApi(app_client, bearer(users.access_token("olga", ("operator",))))


def bucket_keys(aws_clients: Any, stack: Any) -> set[str]:
    bucket = stack.buckets["models"]
    reply = aws_clients.s3.list_objects_v2(Bucket=bucket)
    return {entry["Key"] for entry in reply.get("Contents", [])}


def test_valid_onnx_upload_becomes_available_with_md5s_and_metadata(racer_a: ModelsApi, aws_clients: Any,
                                                                    stack: Any) -> None:
    archive = onnx_archive()
    model = racer_a.upload_and_complete("Speedy_1.tar.gz", archive)

    assert model["status"] == "AVAILABLE" and model["reason"] is None
    assert model["name"] == "Speedy_1" and model["owner_username"] == "alice"
    assert model["model_kind"] == "onnx"
    assert model["model_md5"] == hashlib.md5(onnx_policy()).hexdigest()
    assert model["archive_md5"] == hashlib.md5(archive).hexdigest()
    assert model["size_bytes"] == len(archive)
    assert model["sensor"] == ["FRONT_FACING_CAMERA"]
    assert (model["action_space_type"], model["training_algorithm"]) == ("continuous", "behaviour_cloning")
    keys = bucket_keys(aws_clients, stack)
    assert any(k.startswith("models/") and k.endswith(f"{model['model_id']}.tar.gz") for k in keys)
    assert not any(k.startswith("uploads/") for k in keys), "the untrusted upload is removed once judged"


def test_archive_without_metadata_is_not_valid_with_a_readable_reason(racer_a: ModelsApi) -> None:
    model = racer_a.upload_and_complete("nometa.tar.gz", archive_without_metadata())
    assert model["status"] == "NOT_VALID"
    assert "model_metadata.json" in model["reason"]


def test_a_zip_file_is_not_valid_and_says_so(racer_a: ModelsApi) -> None:
    model = racer_a.upload_and_complete("zipped.tar.gz", b"PK\x03\x04" + b"\x00" * 200)
    assert model["status"] == "NOT_VALID" and "zip" in model["reason"]


def test_traversal_archive_is_quarantined_and_never_lands_under_models(racer_a: ModelsApi, aws_clients: Any,
                                                                      stack: Any) -> None:
    model = racer_a.upload_and_complete("evil.tar.gz", traversal_archive())

    assert model["status"] == "QUARANTINED" and ".." in model["reason"]
    keys = bucket_keys(aws_clients, stack)
    assert not any(k.startswith("models/") for k in keys)
    assert any(k.startswith("quarantine/") and model["model_id"] in k for k in keys)
    # and a quarantined model cannot be given to a car (see test_assignments) nor listed as available
    listed = racer_a.list().json_body["models"]
    assert [m["status"] for m in listed] == ["QUARANTINED"]


def test_complete_is_idempotent(racer_a: ModelsApi) -> None:
    model = racer_a.upload("again.tar.gz", onnx_archive())
    first = racer_a.complete(model["model_id"])
    second = racer_a.complete(model["model_id"])
    assert first.status_code == second.status_code == 200
    assert first.json_body == second.json_body
    assert second.json_body["model"]["status"] == "AVAILABLE"


def test_complete_before_the_file_arrived_is_a_conflict_and_can_be_retried(racer_a: ModelsApi) -> None:
    ticket = racer_a.request_upload("late.tar.gz").json_body
    early = racer_a.complete(ticket["model"]["model_id"])
    assert early.status_code == 409 and "has not arrived" in early.json_body["error"]["message"]
    assert racer_a.get(ticket["model"]["model_id"]).json_body["model"]["status"] == "UPLOADED"


def test_upload_ticket_is_a_size_limited_presigned_post_for_the_callers_prefix(racer_a: ModelsApi) -> None:
    ticket = racer_a.request_upload("ticket.tar.gz").json_body
    fields = ticket["upload"]["fields"]
    assert fields["key"].startswith("uploads/") and fields["key"].endswith(f"/{ticket['model']['model_id']}.tar.gz")
    assert fields["x-amz-algorithm"] == "AWS4-HMAC-SHA256"
    policy = json.loads(base64.b64decode(fields["policy"]))
    assert ["content-length-range", 1, ticket["max_bytes"]] in policy["conditions"]
    assert ticket["model"]["status"] == "UPLOADED"


@pytest.mark.parametrize("filename", ["my model.tar.gz", "../x.tar.gz", "model.zip", "a.b.tar.gz", ""])
def test_bad_file_names_are_refused_naming_the_field(racer_a: ModelsApi, filename: str) -> None:
    reply = racer_a.request_upload(filename)
    assert reply.status_code == 400
    assert "filename" in reply.json_body["error"]["fields"]


def test_duplicate_of_an_available_model_is_recognised_and_not_kept(racer_a: ModelsApi, racer_b: ModelsApi) -> None:
    first = racer_a.upload_and_complete("original.tar.gz", onnx_archive(0.5))
    copy = racer_a.upload_and_complete("copy.tar.gz", onnx_archive(0.5))

    assert copy["status"] == "NOT_VALID"
    assert copy["duplicate_of"] == {"model_id": first["model_id"], "name": "original"}
    assert "original" in copy["reason"]
    available = [m for m in racer_a.list().json_body["models"] if m["status"] == "AVAILABLE"]
    assert [m["model_id"] for m in available] == [first["model_id"]]
    # another racer's identical model is theirs, not a duplicate
    assert racer_b.upload_and_complete("original.tar.gz", onnx_archive(0.5))["status"] == "AVAILABLE"


def test_racer_sees_only_own_models_newest_first(racer_a: ModelsApi, racer_b: ModelsApi) -> None:
    a1 = racer_a.upload_and_complete("a1.tar.gz", onnx_archive(1))
    a2 = racer_a.upload_and_complete("a2.tar.gz", onnx_archive(2))
    b1 = racer_b.upload_and_complete("b1.tar.gz", onnx_archive(3))

    assert [m["model_id"] for m in racer_a.list().json_body["models"]] == [a2["model_id"], a1["model_id"]]
    assert [m["model_id"] for m in racer_b.list().json_body["models"]] == [b1["model_id"]]


def test_racer_b_cannot_read_complete_or_delete_racer_as_model(racer_a: ModelsApi, racer_b: ModelsApi) -> None:
    model = racer_a.upload("mine.tar.gz", onnx_archive())
    assert racer_b.complete(model["model_id"]).status_code == 403
    assert racer_b.get(model["model_id"]).status_code == 403
    assert racer_b.delete(model["model_id"]).status_code == 403
    assert racer_a.get(model["model_id"]).json_body["model"]["status"] == "UPLOADED", "B's complete did nothing"
    assert racer_b.get("no-such-model").status_code == 404


def test_operator_sees_everyones_models_newest_first_in_pages(racer_a: ModelsApi, racer_b: ModelsApi,
                                                               operator: ModelsApi) -> None:
    made = [racer_a.upload_and_complete("m0.tar.gz", onnx_archive(10)),
            racer_b.upload_and_complete("m1.tar.gz", onnx_archive(11)),
            racer_a.upload_and_complete("m2.tar.gz", onnx_archive(12))]
    expected = [m["model_id"] for m in reversed(made)]

    first = operator.list("?limit=2").json_body
    assert [m["model_id"] for m in first["models"]] == expected[:2] and first["next"]
    second = operator.list(f"?limit=2&next={first['next']}").json_body
    assert [m["model_id"] for m in second["models"]] == expected[2:]
    assert {m["owner_username"] for m in first["models"] + second["models"]} == {"alice", "bob"}


def test_a_page_token_from_another_listing_is_refused(racer_a: ModelsApi, operator: ModelsApi) -> None:
    for bias in (1, 2):
        racer_a.upload_and_complete(f"t{bias}.tar.gz", onnx_archive(bias))
    operator_token = operator.list("?limit=1").json_body["next"]
    reply = racer_a.list(f"?limit=1&next={operator_token}")
    assert reply.status_code == 400 and reply.json_body["error"]["field"] == "next"
    assert racer_a.list("?next=garbage!").status_code == 400


def test_soft_delete_hides_the_model_from_owner_and_operator_listings(racer_a: ModelsApi,
                                                                     operator: ModelsApi) -> None:
    keep = racer_a.upload_and_complete("keep.tar.gz", onnx_archive(1))
    gone = racer_a.upload_and_complete("gone.tar.gz", onnx_archive(2))

    deleted = racer_a.delete(gone["model_id"])
    assert deleted.status_code == 200 and deleted.json_body["model"]["status"] == "DELETED"
    assert [m["model_id"] for m in racer_a.list().json_body["models"]] == [keep["model_id"]]
    assert [m["model_id"] for m in operator.list().json_body["models"]] == [keep["model_id"]]
    assert racer_a.get(gone["model_id"]).status_code == 404
    assert racer_a.delete(gone["model_id"]).status_code == 404
    # once deleted, the same model file may be uploaded again
    assert racer_a.upload_and_complete("gone.tar.gz", onnx_archive(2))["status"] == "AVAILABLE"


def test_anonymous_callers_are_refused(app_client: Client) -> None:
    anonymous = ModelsApi(app_client, {"Accept": "application/json"})
    assert anonymous.list().status_code == 401


def test_gzip_of_a_tar_with_a_symlink_is_quarantined(racer_a: ModelsApi) -> None:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as archive:
        info = tarfile.TarInfo("model.onnx")
        info.type, info.linkname = tarfile.SYMTYPE, "/etc/shadow"
        archive.addfile(info)
    model = racer_a.upload_and_complete("link.tar.gz", gzip.compress(buffer.getvalue()))
    assert model["status"] == "QUARANTINED" and "symbolic link" in model["reason"]
