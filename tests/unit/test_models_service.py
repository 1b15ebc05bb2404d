"""The model service below the HTTP layer: the S3 event path, the size limit we enforce ourselves, sample seeding."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from chalicelib import services
from chalicelib.core.principals import User
from chalicelib.domain.racer_models import ListQuery, ModelStatus, UploadRequest, seed_sample_models
from chalicelib.formats.model_archive.limits import ArchiveLimits
from chalicelib.routes.racer_models import handle_upload_complete_event
from tests.unit.models_helpers import onnx_archive, traversal_archive

pytestmark = pytest.mark.unit

ALICE = User(sub="sub-alice", username="alice", groups=frozenset({"racer"}))


def s3_event(bucket: str, key: str) -> dict[str, Any]:
    return {"version": "0", "source": "aws.s3", "detail-type": "Object Created",
            "detail": {"bucket": {"name": bucket}, "object": {"key": key, "size": 1}}}


def test_eventbridge_object_created_validates_the_upload(stack: Any, aws_clients: Any) -> None:
    service = services.model_service()
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
    service = services.model_service(limits=limits)
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
    service = services.model_service()

    first = seed_sample_models(service, [good, evil])
    again = seed_sample_models(service, [good, evil])

    assert [(m.name, m.owner_username, m.status) for m in first] == [
        ("Centerline-AtoZ", "default", ModelStatus.AVAILABLE), ("evil", "default", ModelStatus.QUARANTINED)]
    assert again == first
    staff = User(sub="sub-op", username="olga", groups=frozenset({"operator"}))
    listed = service.list_models(staff, ListQuery())
    assert sorted(m.name for m in listed.models) == ["Centerline-AtoZ", "evil"]


class SteppedClock:
    """The service's clock (ISO text, as records store it), moved by hand."""

    def __init__(self) -> None:
        from datetime import UTC, datetime

        self.now = datetime(2026, 5, 14, 9, 0, tzinfo=UTC)

    def __call__(self) -> str:
        return self.now.strftime("%Y-%m-%dT%H:%M:%S.%fZ")

    def advance(self, **delta: float) -> None:
        from datetime import timedelta

        self.now += timedelta(**delta)


def _objects(aws_clients: Any, bucket: str) -> list[str]:
    return [o["Key"] for o in aws_clients.s3.list_objects_v2(Bucket=bucket).get("Contents", [])]


def test_an_upload_never_completed_is_purged_with_its_object_once_its_link_is_long_expired(stack: Any,
                                                                                           aws_clients: Any) -> None:
    from chalicelib.domain.racer_models import STALE_UPLOAD_AFTER_S

    clock = SteppedClock()
    service = services.model_service(clock=clock)
    bucket = stack.buckets["models"]
    abandoned = service.request_upload(ALICE, UploadRequest(filename="abandoned.tar.gz"))
    aws_clients.s3.put_object(Bucket=bucket, Key=abandoned.model.upload_key, Body=os.urandom(4096))  # never completed
    clock.advance(seconds=STALE_UPLOAD_AFTER_S - 60)
    recent = service.request_upload(ALICE, UploadRequest(filename="recent.tar.gz"))
    assert service.store.get(ALICE.sub, abandoned.model.model_id).status is ModelStatus.UPLOADED  # not yet stale

    clock.advance(seconds=120)
    still_pending = service.purge_stale_uploads()

    purged = service.store.get(ALICE.sub, abandoned.model.model_id)
    assert purged.status is ModelStatus.DELETED and "never completed" in (purged.reason or "")
    assert abandoned.model.upload_key not in _objects(aws_clients, bucket)
    assert [r.model_id for r in still_pending] == [recent.model.model_id]
    assert [m.model_id for m in service.list_models(ALICE, ListQuery()).models] == [recent.model.model_id]


def test_a_racer_cannot_hold_more_than_a_few_open_upload_tickets(stack: Any, aws_clients: Any) -> None:
    from chalicelib.core.errors import RateLimited
    from chalicelib.domain.racer_models import MAX_PENDING_UPLOADS, STALE_UPLOAD_AFTER_S

    clock = SteppedClock()
    service = services.model_service(clock=clock)
    tickets = [service.request_upload(ALICE, UploadRequest(filename=f"m{i}.tar.gz"))
               for i in range(MAX_PENDING_UPLOADS)]

    with pytest.raises(RateLimited) as refused:
        service.request_upload(ALICE, UploadRequest(filename="one-more.tar.gz"))
    assert f"You have {MAX_PENDING_UPLOADS} uploads that were never completed" in refused.value.message

    # Completing one (the legitimate path) frees a place; so does the wait for the others to go stale.
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=tickets[0].model.upload_key, Body=onnx_archive())
    assert service.complete(ALICE, tickets[0].model.model_id).status is ModelStatus.AVAILABLE
    service.request_upload(ALICE, UploadRequest(filename="after-completing.tar.gz"))
    clock.advance(seconds=STALE_UPLOAD_AFTER_S + 1)
    service.request_upload(ALICE, UploadRequest(filename="after-the-wait.tar.gz"))


def test_deleting_a_pending_upload_removes_what_was_uploaded(stack: Any, aws_clients: Any) -> None:
    service = services.model_service()
    ticket = service.request_upload(ALICE, UploadRequest(filename="changed-my-mind.tar.gz"))
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=ticket.model.upload_key, Body=onnx_archive())

    service.delete(ALICE, ticket.model.model_id)

    assert _objects(aws_clients, stack.buckets["models"]) == []


class _PowerCut(BaseException):
    """What a kill -9 of the app looks like to the code that was running: it never gets to its next line."""


class _CutDuringCopy:
    """The model files, with the app killed while the checked archive is copied into models/ (the check's last
    step before its verdict is written)."""

    def __init__(self, files: Any) -> None:
        self._files = files

    def __getattr__(self, name: str) -> Any:
        return getattr(self._files, name)

    def copy(self, source: str, destination: str) -> None:
        raise _PowerCut()


def test_a_check_cut_short_by_a_crash_is_finished_by_the_worker_and_the_row_says_so(stack: Any,
                                                                                       aws_clients: Any) -> None:
    from chalicelib.domain.racer_models import CHECK_STALE_AFTER_S

    clock = SteppedClock()
    service = services.model_service(clock=clock)
    ticket = service.request_upload(ALICE, UploadRequest(filename="interrupted.tar.gz"))
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=ticket.model.upload_key, Body=onnx_archive())
    assert service.store.get(ALICE.sub, ticket.model.model_id).check_state(clock()) == "waiting"

    crashing = services.model_service(clock=clock)
    crashing.files = _CutDuringCopy(crashing.files)
    with pytest.raises(_PowerCut):
        crashing.complete(ALICE, ticket.model.model_id)
    left = service.store.get(ALICE.sub, ticket.model.model_id)
    assert left.status is ModelStatus.UPLOADED and left.check_attempts == 1
    assert left.check_state(clock()) == "checking"
    assert service.resume_checks() == []  # a check that may still be running is left alone

    clock.advance(seconds=CHECK_STALE_AFTER_S + 1)
    assert left.check_state(clock()) == "interrupted"
    assert service.purge_stale_uploads() == [left]  # never purged as "never completed": its file arrived
    finished = service.resume_checks()

    assert [(m.model_id, m.status) for m in finished] == [(ticket.model.model_id, ModelStatus.AVAILABLE)]
    stored = service.store.get(ALICE.sub, ticket.model.model_id)
    assert stored.status is ModelStatus.AVAILABLE and stored.check_attempts == 2 and stored.s3_key
    assert ticket.model.upload_key not in _objects(aws_clients, stack.buckets["models"])


def test_an_archive_whose_check_keeps_crashing_the_server_ends_not_valid_instead_of_looping(stack: Any,
                                                                                            aws_clients: Any) -> None:
    from chalicelib.domain.racer_models import CHECK_STALE_AFTER_S, MAX_CHECK_ATTEMPTS

    clock = SteppedClock()
    crashing = services.model_service(clock=clock)
    crashing.files = _CutDuringCopy(crashing.files)
    ticket = crashing.request_upload(ALICE, UploadRequest(filename="poison.tar.gz"))
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=ticket.model.upload_key, Body=onnx_archive())
    for _attempt in range(MAX_CHECK_ATTEMPTS):
        clock.advance(seconds=CHECK_STALE_AFTER_S + 1)
        with pytest.raises(_PowerCut):
            crashing.resume_checks()

    clock.advance(seconds=CHECK_STALE_AFTER_S + 1)
    [ended] = services.model_service(clock=clock).resume_checks()
    assert ended.status is ModelStatus.NOT_VALID and "interrupted 3 times" in (ended.reason or "")
    assert ticket.model.upload_key not in _objects(aws_clients, stack.buckets["models"])
