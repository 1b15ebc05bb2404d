"""The model service below the HTTP layer: the S3 event path, the size limit we enforce ourselves, sample seeding."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from chalicelib.auth.principals import User
from chalicelib.domain.model_archive import ArchiveLimits
from chalicelib.domain.models import ListQuery, ModelStatus, UploadRequest, seed_sample_models
from chalicelib.routes.models import handle_upload_complete_event
from chalicelib.storage.models import build_model_service
from tests.unit.models_helpers import onnx_archive, traversal_archive

pytestmark = pytest.mark.unit

ALICE = User(sub="sub-alice", username="alice", groups=frozenset({"racer"}))


def s3_event(bucket: str, key: str) -> dict[str, Any]:
    return {"version": "0", "source": "aws.s3", "detail-type": "Object Created",
            "detail": {"bucket": {"name": bucket}, "object": {"key": key, "size": 1}}}


def test_eventbridge_object_created_validates_the_upload(stack: Any, aws_clients: Any) -> None:
    service = build_model_service()
    ticket = service.request_upload(ALICE, UploadRequest(filename="evented.tar.gz"))
    key, bucket = ticket.model.upload_key, stack.buckets["models"]
    aws_clients.s3.put_object(Bucket=bucket, Key=key, Body=onnx_archive())

    assert handle_upload_complete_event(s3_event(bucket, key)) == {"model_id": ticket.model.model_id,
                                                                   "status": "AVAILABLE"}
    # the explicit call after the event (the uploader does both locally-style) returns the same verdict
    assert service.complete(ALICE, ticket.model.model_id).status is ModelStatus.AVAILABLE
    # a redelivered event changes nothing
    assert handle_upload_complete_event(s3_event(bucket, key))["status"] == "AVAILABLE"


def test_events_for_other_buckets_or_unknown_keys_are_ignored(stack: Any, aws_clients: Any) -> None:
    bucket = stack.buckets["models"]
    assert handle_upload_complete_event(s3_event("someone-elses-bucket", "uploads/x/y.tar.gz")) == {"ignored": True}
    assert handle_upload_complete_event(s3_event(bucket, "uploads/nobody/nothing.tar.gz")) == {"ignored": True}
    assert handle_upload_complete_event(s3_event(bucket, "models/../../etc")) == {"ignored": True}


def test_the_size_limit_is_enforced_by_us_not_by_the_presigned_policy(stack: Any, aws_clients: Any) -> None:
    limits = ArchiveLimits(max_compressed_bytes=4096)
    service = build_model_service(limits=limits)
    ticket = service.request_upload(ALICE, UploadRequest(filename="huge.tar.gz"))
    assert ticket.max_bytes == 4096
    # moto ignores the policy's content-length-range, exactly like a misconfigured bucket would
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=ticket.model.upload_key, Body=os.urandom(5000))

    verdict = service.complete(ALICE, ticket.model.model_id)
    assert verdict.status is ModelStatus.NOT_VALID
    assert "limited to" in (verdict.reason or "")
    listed = aws_clients.s3.list_objects_v2(Bucket=stack.buckets["models"]).get("Contents", [])
    assert listed == [], "an oversized upload is discarded, never copied under models/"


def test_bounded_download_stops_just_past_the_limit_whatever_the_object_says(stack: Any, aws_clients: Any) -> None:
    from chalicelib.storage import clients
    from chalicelib.storage.model_files import S3ModelFiles

    bucket = stack.buckets["models"]
    aws_clients.s3.put_object(Bucket=bucket, Key="uploads/x/big.tar.gz", Body=os.urandom(50_000))
    files = S3ModelFiles(clients.s3(), bucket)

    download = files.download_bounded("uploads/x/big.tar.gz", limit=4096)
    assert download is not None and download.too_large and download.size == 4097
    assert len(download.body.read()) == 4097
    assert files.download_bounded("uploads/x/missing.tar.gz", limit=4096) is None


def test_seed_sample_models_is_idempotent_and_validates_like_any_upload(stack: Any, tmp_path: Path) -> None:
    good, evil = tmp_path / "Centerline-AtoZ.tar.gz", tmp_path / "evil.tar.gz"
    good.write_bytes(onnx_archive(0.5))
    evil.write_bytes(traversal_archive())
    service = build_model_service()

    first = seed_sample_models(service, [good, evil])
    again = seed_sample_models(service, [good, evil])

    assert [(m.name, m.owner_username, m.status) for m in first] == [
        ("Centerline-AtoZ", "default", ModelStatus.AVAILABLE), ("evil", "default", ModelStatus.QUARANTINED)]
    assert again == first
    staff = User(sub="sub-op", username="olga", groups=frozenset({"operator"}))
    listed = service.list_models(staff, ListQuery())
    assert sorted(m.name for m in listed.models) == ["Centerline-AtoZ", "evil"]
