"""Racers' model archives: upload tickets, validation on completion, listing, soft delete, sample seeding.

Lifecycle: UPLOADED (ticket issued; the bytes may or may not have arrived) → AVAILABLE | NOT_VALID (reason the racer
can act on) | QUARANTINED (the archive could write outside a sandbox; moved to `quarantine/`, never served);
DELETED on soft delete. Completion is idempotent: once a verdict is stored, completing again returns it unchanged.

Duplicates: an archive whose model file has the same md5 as one of the owner's AVAILABLE models is not kept. Its
record becomes NOT_VALID with `duplicate_of` naming the earlier model, and its upload is deleted, so one model file
never has two AVAILABLE records (and never appears twice in the car-assignment picker).
"""
from __future__ import annotations

import hashlib
import logging
import re
import secrets
from collections.abc import Callable, Iterator
from datetime import UTC, datetime, timedelta
from enum import StrEnum
from pathlib import Path
from typing import IO, Any, NoReturn, Protocol

from pydantic import BaseModel, ConfigDict, Field, field_validator

from chalicelib import logs
from chalicelib.core.errors import Conflict, InvalidInput, NotFound, RateLimited
from chalicelib.core.principals import Principal, Role
from chalicelib.domain.model_conversion import ConversionOutcome
from chalicelib.domain.ownership import require_owner_or_role
from chalicelib.formats.model_archive.limits import DEFAULT_LIMITS, ArchiveLimits
from chalicelib.formats.model_archive.names import model_name_from_filename
from chalicelib.formats.model_archive.report import ArchiveStatus
from chalicelib.formats.model_archive.verdict import inspect_archive

SAMPLE_OWNER = "default"
UPLOAD_EXPIRES_S = 15 * 60
# An upload still not completed this long after its ticket was issued can never arrive any more (the signed POST
# expired an hour before): its record and any object it left are purged.
STALE_UPLOAD_AFTER_S = UPLOAD_EXPIRES_S + 60 * 60
# Upload tickets a racer may hold open at once: each lets up to max_upload_bytes land in the bucket before anything
# judges it, so an open-ended number would let one racer fill the disk.
MAX_PENDING_UPLOADS = 5
DOWNLOAD_EXPIRES_S = 5 * 60
# A check runs for at most a minute or so (the console conversion's own bound is 60 s of wall clock); one started
# longer ago than this was cut short (the app or storage was killed) and is started again.
CHECK_STALE_AFTER_S = 180
# Checks that were cut short this many times end the upload as NOT_VALID instead of trying forever: an archive
# whose check brings the server down every time must not do so again at every restart.
MAX_CHECK_ATTEMPTS = 3
MODEL_ID_PATTERN = r"^[A-Za-z0-9_-]{1,80}$"
# Who may see and act on every racer's models.
MODEL_STAFF = frozenset({Role.ADMIN, Role.OPERATOR})


class ModelStatus(StrEnum):
    UPLOADED = "UPLOADED"
    AVAILABLE = "AVAILABLE"
    NOT_VALID = "NOT_VALID"
    QUARANTINED = "QUARANTINED"
    DELETED = "DELETED"


class ModelRef(BaseModel):
    model_config = ConfigDict(frozen=True)
    model_id: str
    name: str


class ScrutineerResult(BaseModel):
    """The last test drive of a model in the simulator, on an event's track."""
    model_config = ConfigDict(frozen=True)
    verdict: str
    message: str  # for the racer: a sentence, never an exception's name
    track: str
    detail: str | None = None  # what the software said when a drive stopped without a verdict: staff only
    track_type: str | None = None
    laps: int = 0  # lap attempts asked for
    laps_completed: int = 0  # whole laps (drem_leaderboard.laps), the same count as `drem sim eval`
    best_lap_time_s: float | None = None
    mean_lap_time_s: float | None = None
    offtrack_count: int = 0
    attempts: int | None = Field(default=None, ge=0)  # lap attempts that ended (None: a report from before they were)
    completion_pct: float | None = Field(default=None, ge=0, le=100, allow_inf_nan=False)  # mean progress per attempt
    at: str = ""


class ModelRecord(BaseModel):
    model_config = ConfigDict(frozen=True)

    model_id: str
    owner_sub: str
    owner_username: str
    name: str
    status: ModelStatus
    uploaded_at: str
    updated_at: str
    upload_key: str
    size_bytes: int = 0
    reason: str | None = None
    model_kind: str | None = None
    model_md5: str | None = None
    metadata_md5: str | None = None
    archive_md5: str | None = None
    sensor: list[str] = Field(default_factory=list)
    action_space_type: str | None = None
    training_algorithm: str | None = None
    duplicate_of: ModelRef | None = None
    # Where the archive lives now: models/... when AVAILABLE, quarantine/... when QUARANTINED.
    s3_key: str | None = None
    # Console models: the ONNX conversion stored beside the untouched archive (models/...onnx), and whether the
    # model can be test-driven in the simulator ("ready") or not ("cannot_scrutineer", with scrutiny_reason).
    converted_key: str | None = None
    converted_md5: str | None = None
    scrutiny: str | None = None
    scrutiny_reason: str | None = None
    scrutiny_detail: str | None = None  # for staff: the converter's own message (OpenVINO's) behind the reason
    conversion_max_diff: float | None = None
    scrutineer_result: ScrutineerResult | None = None
    # The background test drive (domain/scrutineer_queue.py): "queued" or "driving" while it has a job, else None;
    # the top-down clip of its last drive (models/...scrutineer.gif), served only to the owner and model staff.
    scrutineer_state: str | None = None
    scrutineer_clip_key: str | None = None
    # The check of an arrived upload (inspection, the console conversion, the copy): when the latest attempt started
    # and how many have started. Written before the check runs, so after a crash of the app or storage the record
    # itself says a check was interrupted; the scrutineering worker resumes it (ModelService.resume_checks).
    check_started_at: str | None = None
    check_attempts: int = 0

    def check_state(self, now: str) -> str:
        """For an UPLOADED model: "waiting" (the file has not been checked yet), "checking" (a check started less
        than CHECK_STALE_AFTER_S ago) or "interrupted" (one started longer ago and never finished: resumed by the
        worker, and staff may start it again). Empty for any other status."""
        if self.status is not ModelStatus.UPLOADED:
            return ""
        if self.check_started_at is None:
            return "waiting"
        started = _parse_time(self.check_started_at)
        return "checking" if _parse_time(now) - started < timedelta(seconds=CHECK_STALE_AFTER_S) else "interrupted"

    @property
    def scrutiny_text(self) -> str:
        if self.scrutiny == "cannot_scrutineer":
            return f"cannot be scrutineered: {self.scrutiny_reason or 'no reason given'}"
        if self.scrutiny == "ready" and self.model_kind == "tensorflow":
            return f"converted to ONNX (agrees with OpenVINO to {self.conversion_max_diff or 0:.1e})"
        return "ready" if self.status is ModelStatus.AVAILABLE else ""

    @property
    def check_text(self) -> str:
        """What an UPLOADED model's row says, true to its record: not checked yet, being checked, or a check that a
        crash cut short (restarted by the worker; staff may start it at once)."""
        return {"waiting": "Waiting to be checked…", "checking": "Checking…",
                "interrupted": "Check interrupted; it restarts by itself"}.get(self.check_state(utc_now()), "")

    @property
    def scrutineer_status(self) -> str:
        """Where the model's test drive stands: queued, driving, passed, failed, cannot_scrutineer (with
        `scrutineer_status_reason`) or not_scrutineered; empty for a model that is not AVAILABLE."""
        if self.status is not ModelStatus.AVAILABLE:
            return ""
        if self.scrutiny == "cannot_scrutineer":
            return "cannot_scrutineer"
        if self.scrutineer_state in ("queued", "driving"):
            return self.scrutineer_state
        if self.scrutineer_result is None:
            return "not_scrutineered"
        verdict = self.scrutineer_result.verdict
        return verdict if verdict in ("passed", "failed") else "cannot_scrutineer"

    @property
    def scrutineer_status_reason(self) -> str | None:
        if self.scrutineer_status != "cannot_scrutineer":
            return None
        if self.scrutiny == "cannot_scrutineer":
            return self.scrutiny_reason or "no reason given"
        return self.scrutineer_result.message if self.scrutineer_result else None

    @property
    def scrutineer_passed(self) -> bool:
        return self.scrutineer_status == "passed"

    def public(self, *, staff: bool = False) -> dict[str, Any]:
        """What API callers see (storage keys stay inside; a stopped drive's technical detail only for staff)."""
        shown = self.model_dump(mode="json", exclude={"upload_key", "s3_key", "converted_key",
                                                      "scrutineer_clip_key"})
        if not staff and shown.get("scrutineer_result"):
            shown["scrutineer_result"].pop("detail", None)
        shown.update(scrutineer_status=self.scrutineer_status, scrutineer_status_reason=self.scrutineer_status_reason,
                     scrutineer_clip=f"/api/models/{self.model_id}/scrutineer/clip.gif"
                     if self.scrutineer_clip_key else None)
        return shown

    def shown_to(self, principal: Principal) -> dict[str, Any]:
        """`public()` for this caller: model staff also get the technical detail of a stopped test drive."""
        return self.public(staff=bool(principal.roles & MODEL_STAFF))


class ModelPage(BaseModel):
    models: list[ModelRecord]
    next_token: str | None = None


class UploadRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    filename: str = Field(max_length=80, description="the archive's file name, e.g. my-model.tar.gz")

    @field_validator("filename")
    @classmethod
    def _valid_name(cls, filename: str) -> str:
        try:
            model_name_from_filename(filename)
        except InvalidInput as exc:  # re-raised as ValueError so the 400 names `filename`
            raise ValueError(exc.message) from None
        return filename

    @property
    def model_name(self) -> str:
        return model_name_from_filename(self.filename)


class ListQuery(BaseModel):
    model_config = ConfigDict(extra="forbid")
    limit: int = Field(default=25, ge=1, le=100)
    next: str | None = Field(default=None, max_length=2048)


class UploadTicket(BaseModel):
    model: ModelRecord
    url: str
    fields: dict[str, str]
    max_bytes: int
    expires_in: int

    def public(self) -> dict[str, Any]:
        return {"model": self.model.public(), "upload": {"url": self.url, "fields": self.fields},
                "max_bytes": self.max_bytes, "expires_in": self.expires_in}


class ModelChanged(Exception):
    """A conditional write lost: someone else changed the record first (the store raises it)."""


class ModelStore(Protocol):
    def create(self, record: ModelRecord) -> None: ...
    def replace(self, record: ModelRecord, *, expected_status: ModelStatus,
                result_as_in: ModelRecord | None = None) -> None: ...
    def get(self, owner_sub: str, model_id: str) -> ModelRecord | None: ...
    def get_by_id(self, model_id: str) -> ModelRecord | None: ...
    def list_owner(self, owner_sub: str, *, limit: int, next_token: str | None,
                   include_deleted: bool = False) -> ModelPage: ...
    def list_all(self, *, limit: int, next_token: str | None) -> ModelPage: ...
    def find_available_by_md5(self, owner_sub: str, model_md5: str) -> list[ModelRecord]: ...


class DownloadLike(Protocol):
    body: IO[bytes]
    size: int
    md5: str
    too_large: bool


class ModelFiles(Protocol):
    def presign_upload(self, key: str, *, max_bytes: int, expires_s: int) -> dict[str, Any]: ...
    def presign_download(self, key: str, *, expires_s: int) -> str: ...
    def size_of(self, key: str) -> int | None: ...
    def download_bounded(self, key: str, *, limit: int) -> DownloadLike | None: ...
    def put(self, key: str, data: bytes) -> None: ...
    def copy(self, source: str, destination: str) -> None: ...
    def delete(self, key: str) -> None: ...


def _parse_time(stamp: str) -> datetime:
    parsed = datetime.fromisoformat(stamp.replace("Z", "+00:00"))
    return parsed if parsed.tzinfo else parsed.replace(tzinfo=UTC)


def utc_now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def new_model_id() -> str:
    # Time first, so a racer's models (sorted by id) list newest first without a second index.
    return f"{int(datetime.now(UTC).timestamp() * 1000):012x}{secrets.token_hex(6)}"


def upload_key(owner_sub: str, model_id: str) -> str:
    return f"uploads/{owner_sub}/{model_id}.tar.gz"


def model_key(owner_sub: str, model_id: str) -> str:
    return f"models/{owner_sub}/{model_id}.tar.gz"


def converted_key(owner_sub: str, model_id: str) -> str:
    return f"models/{owner_sub}/{model_id}.onnx"


def scrutineer_clip_key(owner_sub: str, model_id: str) -> str:
    return f"models/{owner_sub}/{model_id}.scrutineer.gif"


def quarantine_key(owner_sub: str, model_id: str) -> str:
    return f"quarantine/{owner_sub}/{model_id}.tar.gz"


def parse_upload_key(key: str) -> tuple[str, str] | None:
    """`uploads/{sub}/{modelId}.tar.gz` → (sub, modelId); anything else → None."""
    parts = key.split("/")
    if len(parts) != 3 or parts[0] != "uploads" or not parts[2].endswith(".tar.gz"):
        return None
    sub, model_id = parts[1], parts[2][: -len(".tar.gz")]
    return (sub, model_id) if sub and model_id else None


def _size(count: int) -> str:
    return f"{count / (1024 * 1024):.1f} MiB" if count >= 1024 * 1024 else f"{count} bytes"


class Converter(Protocol):
    def convert(self, archive: IO[bytes]) -> ConversionOutcome: ...
    def warm_up(self) -> None: ...  # an upload is on its way: get ready (a spare worker process)


class ScrutinyEnqueuer(Protocol):
    def queue_for_scrutiny(self, record: ModelRecord) -> ModelRecord: ...  # the record marked "queued"


class ModelService:
    def __init__(self, store: ModelStore, files: ModelFiles, *, limits: ArchiveLimits = DEFAULT_LIMITS,
                 clock: Callable[[], str] = utc_now, new_id: Callable[[], str] = new_model_id,
                 converter: Converter | None = None, scrutineer_queue: ScrutinyEnqueuer | None = None) -> None:
        self.store = store
        self.files = files
        self.limits = limits
        self.converter = converter
        self.scrutineer_queue = scrutineer_queue
        self._clock = clock
        self._new_id = new_id
        # The worker's tests shorten it (DREM_CHECK_STALE_AFTER_S).
        self.check_stale_after_s: float = CHECK_STALE_AFTER_S

    def now(self) -> str:
        return self._clock()

    @property
    def max_upload_bytes(self) -> int:
        return self.limits.max_compressed_bytes

    # -- upload ----------------------------------------------------------------------------------------------------

    def request_upload(self, principal: Principal, request: UploadRequest) -> UploadTicket:
        owner_sub, username = _user_of(principal)
        if self.converter is not None:
            self.converter.warm_up()  # a console model's conversion will not wait for OpenVINO to load
        pending = self.purge_stale_uploads(owner_sub)
        if len(pending) >= MAX_PENDING_UPLOADS:
            raise RateLimited(f"You have {len(pending)} uploads that were never completed; finish or delete one "
                              f"(or wait {STALE_UPLOAD_AFTER_S // 60} minutes for them to expire) before starting "
                              "another.", field="filename")
        record = self._new_record(owner_sub, username, request.model_name, self._new_id())
        self.store.create(record)
        post = self.files.presign_upload(record.upload_key, max_bytes=self.max_upload_bytes,
                                         expires_s=UPLOAD_EXPIRES_S)
        return UploadTicket(model=record, url=post["url"], fields=post["fields"], max_bytes=self.max_upload_bytes,
                            expires_in=UPLOAD_EXPIRES_S)

    def complete(self, principal: Principal, model_id: str) -> ModelRecord:
        record = self._visible(principal, model_id)
        return self._finish(record)

    def complete_upload_key(self, key: str) -> ModelRecord | None:
        """The S3 "Object Created" path (EventBridge on AWS): same work as `complete`, found by key."""
        parsed = parse_upload_key(key)
        record = self.store.get(*parsed) if parsed else None
        if record is None:
            logs.log(logging.WARNING, "model upload for no known model ignored", key=key)
            return None
        try:
            return self._finish(record)
        except Conflict:
            return self.store.get(record.owner_sub, record.model_id)

    def _finish(self, record: ModelRecord) -> ModelRecord:
        if record.status is not ModelStatus.UPLOADED:
            return record
        try:
            record = self._mark_check_started(record)
            if record.status is not ModelStatus.UPLOADED:
                return record
            verdict = self._judge(record)
        except _AlreadyJudged as judged:
            return judged.record
        if (self.scrutineer_queue is not None and verdict.status is ModelStatus.AVAILABLE
                and verdict.scrutiny == "ready"):
            # The job first: a crash before the record is written leaves a job the worker drops or drives, never a
            # record saying "queued" with nothing in the queue.
            verdict = self.scrutineer_queue.queue_for_scrutiny(verdict)
        try:
            self.store.replace(verdict, expected_status=ModelStatus.UPLOADED)
        except ModelChanged:
            return self._reread(record)
        self.files.delete(record.upload_key)
        logs.log(logging.INFO, "model judged", model_id=record.model_id, status=verdict.status.value,
                 reason=verdict.reason)
        return verdict

    def _mark_check_started(self, record: ModelRecord) -> ModelRecord:
        """Record that a check of the arrived upload starts now (the durable mark a crash leaves behind), or end an
        upload whose checks were cut short MAX_CHECK_ATTEMPTS times. Returns the stored record."""
        if self.files.size_of(record.upload_key) is None:
            self._raise_not_arrived(record)
        now = self._clock()
        if record.check_attempts >= MAX_CHECK_ATTEMPTS:
            ended = self._verdict(record, ModelStatus.NOT_VALID, reason=(
                f"checking this archive was interrupted {record.check_attempts} times (the server stopped during the "
                "check each time), so it was not added; upload it again, or ask staff to look at the server's log"))
            try:
                self.store.replace(ended, expected_status=ModelStatus.UPLOADED)
            except ModelChanged:
                return self._reread(record)
            self.files.delete(record.upload_key)
            return ended
        marked = record.model_copy(update={"check_started_at": now, "check_attempts": record.check_attempts + 1,
                                           "updated_at": now})
        try:
            self.store.replace(marked, expected_status=ModelStatus.UPLOADED)
        except ModelChanged:
            return self._reread(record)
        return marked

    def resume_checks(self) -> list[ModelRecord]:
        """Finish the checks nobody is running: uploads whose check started more than CHECK_STALE_AFTER_S ago and
        never ended (the app or storage was killed during it), and files that arrived but were never checked that
        long after their ticket (the browser went away before it could ask). The scrutineering worker calls this
        every little while, so no model stays "Checking…" after a crash. Returns the records it judged."""
        now = _parse_time(self._clock())
        stale = timedelta(seconds=self.check_stale_after_s)
        finished: list[ModelRecord] = []
        for record in self._all_records(None):
            if record.status is not ModelStatus.UPLOADED:
                continue
            since = record.check_started_at or record.uploaded_at
            if now - _parse_time(since) < stale or self.files.size_of(record.upload_key) is None:
                continue
            logs.log(logging.INFO, "resuming an interrupted model check", model_id=record.model_id,
                     attempts=record.check_attempts)
            try:
                finished.append(self._finish(record))
            except Conflict:
                continue  # deleted or judged meanwhile
        return finished

    def _judge(self, record: ModelRecord) -> ModelRecord:
        """Read the upload (bounded), inspect it and put the archive where its verdict says. Writes no record."""
        limit = self.max_upload_bytes
        declared = self.files.size_of(record.upload_key)
        if declared is None:
            self._raise_not_arrived(record)
        if declared > limit:
            return self._verdict(record, ModelStatus.NOT_VALID, size_bytes=declared,
                                 reason=f"the archive is {_size(declared)}; uploads are limited to {_size(limit)}")
        download = self.files.download_bounded(record.upload_key, limit=limit)
        if download is None:
            self._raise_not_arrived(record)
        assert download is not None
        with download.body:  # read once: the inspection and a console model's conversion share this copy
            if download.too_large:  # the object grew after the size check: trust only what we read
                return self._verdict(record, ModelStatus.NOT_VALID, size_bytes=download.size,
                                     reason=f"the archive is larger than the {_size(limit)} upload limit")
            report = inspect_archive(download.body, limits=self.limits)
            facts: dict[str, Any] = dict(size_bytes=download.size, archive_md5=download.md5, reason=report.reason)
            if report.status is ArchiveStatus.QUARANTINED:
                destination = quarantine_key(record.owner_sub, record.model_id)
                self.files.copy(record.upload_key, destination)
                return self._verdict(record, ModelStatus.QUARANTINED, s3_key=destination, **facts)
            if report.status is ArchiveStatus.NOT_VALID:
                return self._verdict(record, ModelStatus.NOT_VALID, **facts)
            facts.update(model_kind=report.model_kind, model_md5=report.model_md5, metadata_md5=report.metadata_md5,
                         sensor=list(report.sensor), action_space_type=report.action_space_type,
                         training_algorithm=report.training_algorithm)
            earlier = [m for m in self.store.find_available_by_md5(record.owner_sub, report.model_md5 or "")
                       if m.model_id != record.model_id]
            if earlier:
                first = earlier[0]
                return self._verdict(record, ModelStatus.NOT_VALID, **{
                    **facts, "duplicate_of": ModelRef(model_id=first.model_id, name=first.name),
                    "reason": f"this is the same model as your model '{first.name}' (identical model file); "
                              "that one is kept, so this copy was not added"})
            if report.model_kind == "tensorflow":
                download.body.seek(0)
                facts.update(self._convert(record, download.body))
                if facts.get("scrutiny") == "not_raceable":  # a stock car cannot load it, or would drive it wrongly
                    return self._verdict(record, ModelStatus.NOT_VALID, **{**facts, "reason": facts["scrutiny_reason"]})
            else:
                facts.update(scrutiny="ready")
        destination = model_key(record.owner_sub, record.model_id)
        self.files.copy(record.upload_key, destination)  # byte for byte: what a stock car receives
        return self._verdict(record, ModelStatus.AVAILABLE, s3_key=destination, **facts)

    def _convert(self, record: ModelRecord, archive: IO[bytes]) -> dict[str, Any]:
        """Console model: convert agent/model.pb to ONNX (contained worker) and store it beside the archive. `archive`
        is the copy `_judge` read (the upload is not downloaded a second time).

        Whatever happens, the model stays AVAILABLE for stock cars; only its scrutiny changes."""
        if self.converter is None:
            return {"scrutiny": "cannot_scrutineer",
                    "scrutiny_reason": "the model converter (OpenVINO) is not installed on this server"}
        outcome = self.converter.convert(archive)
        facts: dict[str, Any] = {"scrutiny": outcome.scrutiny, "scrutiny_reason": outcome.reason,
                                 "scrutiny_detail": outcome.detail, "conversion_max_diff": outcome.max_abs_diff}
        if outcome.scrutiny == "ready" and outcome.onnx:
            key = converted_key(record.owner_sub, record.model_id)
            self.files.put(key, outcome.onnx)
            facts["converted_key"] = key
            facts["converted_md5"] = hashlib.md5(outcome.onnx, usedforsecurity=False).hexdigest()
        logs.log(logging.INFO, "console model converted", model_id=record.model_id, scrutiny=outcome.scrutiny,
                 reason=outcome.reason, detail=outcome.detail, max_abs_diff=outcome.max_abs_diff,
                 seconds=outcome.seconds)
        return facts

    def _verdict(self, record: ModelRecord, status: ModelStatus, **facts: Any) -> ModelRecord:
        return record.model_copy(update={"status": status, "updated_at": self._clock(), **facts})

    def _raise_not_arrived(self, record: ModelRecord) -> NoReturn:
        latest = self._reread(record)
        if latest.status is not ModelStatus.UPLOADED:
            raise _AlreadyJudged(latest)
        raise Conflict(f"The file for model '{record.name}' has not arrived yet: upload it with the presigned POST "
                       "first, then complete the upload.", field="model_id")

    def _reread(self, record: ModelRecord) -> ModelRecord:
        latest = self.store.get(record.owner_sub, record.model_id)
        if latest is None:
            raise NotFound("This model no longer exists.", field="model_id")
        return latest

    # -- reading and deleting --------------------------------------------------------------------------------------

    def list_models(self, principal: Principal, query: ListQuery) -> ModelPage:
        if principal.roles & MODEL_STAFF:
            return self.store.list_all(limit=query.limit, next_token=query.next)
        owner_sub, _ = _user_of(principal)
        return self.store.list_owner(owner_sub, limit=query.limit, next_token=query.next)

    def get(self, principal: Principal, model_id: str) -> ModelRecord:
        return self._visible(principal, model_id)

    def delete(self, principal: Principal, model_id: str) -> ModelRecord:
        record = self._visible(principal, model_id)
        deleted = record.model_copy(update={"status": ModelStatus.DELETED, "updated_at": self._clock()})
        try:
            self.store.replace(deleted, expected_status=record.status)
        except ModelChanged:
            return self.delete(principal, model_id)
        if record.status is ModelStatus.UPLOADED:  # nothing will ever judge (and so remove) what was uploaded
            self.files.delete(record.upload_key)
        return deleted

    def purge_stale_uploads(self, owner_sub: str | None = None) -> list[ModelRecord]:
        """Purge uploads never completed within STALE_UPLOAD_AFTER_S (their object deleted, the record DELETED with
        the reason), for one owner or, with None, for everyone; returns the uploads still pending."""
        cutoff = (_parse_time(self._clock()) - timedelta(seconds=STALE_UPLOAD_AFTER_S))
        pending: list[ModelRecord] = []
        for record in self._all_records(owner_sub):
            if record.status is not ModelStatus.UPLOADED:
                continue
            if _parse_time(record.uploaded_at) > cutoff or record.check_started_at is not None:
                pending.append(record)  # a file whose check started arrived: resume_checks finishes it, never this
                continue
            purged = record.model_copy(update={
                "status": ModelStatus.DELETED, "updated_at": self._clock(),
                "reason": "the upload was never completed before its link expired; it was removed"})
            try:
                self.store.replace(purged, expected_status=ModelStatus.UPLOADED)
            except ModelChanged:
                continue  # completed (or deleted) meanwhile: not stale after all
            self.files.delete(record.upload_key)
            logs.log(logging.INFO, "stale upload purged", model_id=record.model_id, owner_sub=record.owner_sub)
        return pending

    def _all_records(self, owner_sub: str | None) -> Iterator[ModelRecord]:
        token: str | None = None
        while True:
            page = self.store.list_owner(owner_sub, limit=100, next_token=token) if owner_sub is not None \
                else self.store.list_all(limit=100, next_token=token)
            yield from page.models
            token = page.next_token
            if not token:
                return

    def available_model(self, model_id: str) -> ModelRecord:
        """A model a car may be given: it exists and is AVAILABLE (for assignments)."""
        record = self.store.get_by_id(_checked_id(model_id))
        if record is None or record.status is ModelStatus.DELETED:
            raise NotFound(f"There is no model {model_id!r}.", field="model_ids")
        if record.status is not ModelStatus.AVAILABLE or record.s3_key is None:
            raise Conflict(f"Model '{record.name}' is {record.status.value}; only AVAILABLE models can be given "
                           "to a car.", field="model_ids")
        return record

    def download_url(self, record: ModelRecord) -> str:
        if record.status is not ModelStatus.AVAILABLE or record.s3_key is None:
            raise Conflict(f"Model '{record.name}' cannot be downloaded ({record.status.value}).")
        return self.files.presign_download(record.s3_key, expires_s=DOWNLOAD_EXPIRES_S)

    def converted_download_url(self, record: ModelRecord) -> str | None:
        """The ONNX conversion of an AVAILABLE console model (drem car agents drive it), if there is one."""
        if record.status is not ModelStatus.AVAILABLE or record.converted_key is None:
            return None
        return self.files.presign_download(record.converted_key, expires_s=DOWNLOAD_EXPIRES_S)

    def _visible(self, principal: Principal, model_id: str) -> ModelRecord:
        """The model if it exists (not deleted) and the caller owns it or is model staff (403 for other racers)."""
        record = self.store.get_by_id(_checked_id(model_id))
        if record is None or record.status is ModelStatus.DELETED:
            raise NotFound(f"There is no model {model_id!r}.", field="model_id")
        require_owner_or_role(principal, record.owner_sub, MODEL_STAFF)
        return record

    def _new_record(self, owner_sub: str, username: str, name: str, model_id: str) -> ModelRecord:
        now = self._clock()
        return ModelRecord(model_id=model_id, owner_sub=owner_sub, owner_username=username, name=name,
                           status=ModelStatus.UPLOADED, uploaded_at=now, updated_at=now,
                           upload_key=upload_key(owner_sub, model_id))

    def submit_archive(self, owner_sub: str, username: str, name: str, data: bytes, *,
                       model_id: str | None = None) -> ModelRecord:
        """A model made for a racer on the server (the booth's trainer): stored as their upload and judged by exactly
        the same validation as one they uploaded themselves. With `model_id` (recorded by the caller beforehand) the
        submit is idempotent: a repeat returns the record already judged, or finishes one a crash left UPLOADED."""
        if len(data) > self.max_upload_bytes:
            raise InvalidInput(f"the archive is {_size(len(data))}; uploads are limited to "
                               f"{_size(self.max_upload_bytes)}", field="archive")
        if model_id is not None and (existing := self.store.get(owner_sub, model_id)) is not None:
            if existing.status is not ModelStatus.UPLOADED:
                return existing
            self.files.put(existing.upload_key, data)
            return self._finish(existing)
        record = self._new_record(owner_sub, username, model_name_from_filename(f"{name}.tar.gz"),
                                  model_id or self._new_id())
        self.store.create(record)
        self.files.put(record.upload_key, data)
        return self._finish(record)

    # -- samples ---------------------------------------------------------------------------------------------------

    def seed_sample(self, archive: Path) -> ModelRecord:
        name = model_name_from_filename(archive.name)
        model_id = f"sample-{name}"
        record = self.store.get(SAMPLE_OWNER, model_id)
        if record is not None and record.status is not ModelStatus.UPLOADED:
            return record  # seeding again changes nothing
        if archive.stat().st_size > self.max_upload_bytes:
            raise InvalidInput(f"sample {archive.name} is larger than the upload limit", field="archives")
        if record is None:
            record = self._new_record(SAMPLE_OWNER, SAMPLE_OWNER, name, model_id)
            self.store.create(record)
        self.files.put(record.upload_key, archive.read_bytes())
        return self._finish(record)


class _AlreadyJudged(Conflict):
    """Internal: another completion stored the verdict while we looked (carries it)."""

    def __init__(self, record: ModelRecord) -> None:
        super().__init__("already judged")
        self.record = record


def seed_sample_models(services: ModelService, archives: list[Path]) -> list[ModelRecord]:
    """Put the sample archives in as models of the pseudo-user `default`, validated like any upload. Idempotent."""
    return [services.seed_sample(Path(archive)) for archive in sorted(archives)]


def _user_of(principal: Principal) -> tuple[str, str]:
    sub, username = getattr(principal, "sub", None), getattr(principal, "username", None)
    if not principal.is_user or not sub or not username:
        raise InvalidInput("Only signed-in users own models.")
    return sub, username


def _checked_id(model_id: str) -> str:
    if not isinstance(model_id, str) or not re.fullmatch(MODEL_ID_PATTERN, model_id):
        raise NotFound(f"There is no model {str(model_id)[:80]!r}.", field="model_id")
    return model_id
