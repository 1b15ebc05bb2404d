"""Scrutineering a racer's model on an event's track: a short simulator test drive before it races.

Console models drive through their ONNX conversion (made at upload, stored beside the untouched archive); drem's own
ONNX models drive as they are. Two ways in:

* in the background (`ScrutinyEnqueuer` + `BackgroundScrutineer`): a model that becomes AVAILABLE is queued
  (domain/scrutineer_queue.py) for the track types of the upcoming events, and the scrutineering worker process
  (drem_local.workers.scrutineer) drives it in a bounded subprocess and stores the figures and a top-down clip;
* on demand ("drive again", `ScrutineerService.scrutineer`): synchronously, a few laps (~seconds each).

Either way the result (laps completed, best lap, off-tracks) is stored on the model so the console, the API and the
CLI all show it.
"""
from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable, Iterable, Mapping
from datetime import date, timedelta
from pathlib import Path
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict, Field

from chalicelib import logs
from chalicelib.core.errors import Conflict, NotFound
from chalicelib.core.principals import Principal
from chalicelib.domain.events import Event
from chalicelib.domain.racer_models import (
    ModelChanged,
    ModelRecord,
    ModelService,
    ModelStatus,
    ScrutineerResult,
    scrutineer_clip_key,
)
from chalicelib.domain.scrutineer_queue import MAX_ATTEMPTS, MAX_TRACKS_PER_JOB, ScrutineerJob, ScrutineerQueue
from chalicelib.formats.league_export import ExportLimits, read_tar_gz

MAX_LAPS = 3
DEFAULT_TRACK_TYPE = "REINVENT_2018"
# The event track types drem_sim has a twin for (drem_sim.learn.scrutineer.EVENT_TRACKS); others drive the fallback.
TRACK_TYPES = ("REINVENT_2018", "REINVENT_2019", "ATOZ_SPEEDWAY", "SUMMIT_SPEEDWAY", "FOREVER_RACEWAY")
_MEMBERS = ("model_metadata.json", "model.onnx")
MAX_CLIP_BYTES = 2 * 1024 * 1024  # the top-down GIF of a background drive; a bigger one is not kept
_READ_LIMITS = ExportLimits(max_file_bytes=128 * 1024 * 1024, max_total_read_bytes=160 * 1024 * 1024)


class ScrutineerRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    event_id: str | None = Field(default=None, max_length=64, description="drive on this event's track type")
    track_type: str | None = Field(default=None, max_length=40, pattern=r"^[A-Z0-9_]+$",
                                   description="or name the track type (default REINVENT_2018)")
    laps: int = Field(default=1, ge=1, le=MAX_LAPS)


class TrackTypes(Protocol):
    def track_type_of(self, event_id: str) -> str: ...


# drive(model folder holding model_metadata.json + model.onnx, track type, laps) -> a drem_sim ScrutineerReport
Drive = Callable[[Path, str, int], Any]
# {sub: the name a page shows} for (sub, sign-in name) pairs, read in one batch: passed in by the route that words the
# warning (chalicelib.views.racer_names), so the domain names racers as the page does without importing views.
RacerNames = Callable[[list[tuple[str, str]]], Mapping[str, str]]


NO_REPORT = ("drem's simulator finished without a report, so your model was not checked. Try “Drive again”; if it "
             "happens again, tell the staff.")


def simulator_drive(folder: Path, track_type: str, laps: int) -> Any:
    """drem_sim's report; every way the drive can stop comes back as a report with a sentence (drem_sim.learn.
    scrutiny_words), so only a missing simulator is refused here."""
    try:
        from drem_sim.learn.scrutineer import scrutineer_for_event
    except ModuleNotFoundError:
        raise Conflict("This drem server has no simulator installed, so models cannot be test-driven here. Tell the "
                       "staff.") from None
    return scrutineer_for_event(folder, track_type, laps)


class ScrutineerService:
    def __init__(self, models: ModelService, tracks: TrackTypes, *, drive: Drive = simulator_drive,
                 queue: ScrutineerQueue | None = None) -> None:
        self.models = models
        self.tracks = tracks
        self.drive = drive
        self.queue = queue

    def scrutineer(self, principal: Principal, model_id: str, request: ScrutineerRequest) -> ModelRecord:
        record = self.models.get(principal, model_id)  # owner or model staff
        if record.status is not ModelStatus.AVAILABLE or record.s3_key is None:
            raise Conflict(f"Model '{record.name}' is {record.status.value}; only AVAILABLE models can be "
                           "scrutineered.", field="model_id")
        if record.scrutiny == "cannot_scrutineer":
            raise Conflict(f"Model '{record.name}' cannot be scrutineered: {record.scrutiny_reason}. It can still "
                           "race on a stock DeepRacer.", field="model_id")
        track_type = (self.tracks.track_type_of(request.event_id) if request.event_id
                      else request.track_type or DEFAULT_TRACK_TYPE)
        with tempfile.TemporaryDirectory(prefix="scrutineer-") as folder:
            self.model_files(record, Path(folder))
            report = self.drive(Path(folder), track_type, request.laps)
        detail = getattr(report, "detail", None)  # drem_sim reports it when a drive stopped without a verdict
        if detail:
            logs.log(logging.WARNING, "scrutineering drive stopped", model_id=record.model_id, detail=detail[:300])
        result = ScrutineerResult(
            verdict=report.verdict, message=report.message, detail=detail, track=report.track,
            track_type=report.track_type,
            laps=report.laps, laps_completed=report.laps_completed, best_lap_time_s=report.best_lap_time_s,
            mean_lap_time_s=report.mean_lap_time_s, offtrack_count=report.offtrack_count,
            attempts=getattr(report, "attempts", None), completion_pct=getattr(report, "completion_pct", None),
            at=self.models.now())
        stored = self.update(record, scrutineer_result=result, scrutineer_state=None)
        if self.queue is not None:  # driven by hand: a background drive still waiting has nothing left to add
            self.queue.drop(record.model_id)
        return stored

    def clip(self, principal: Principal, model_id: str) -> bytes:
        """The clip of the model's last drive (owner or model staff; another racer gets 403)."""
        record = self.models.get(principal, model_id)
        download = (self.models.files.download_bounded(record.scrutineer_clip_key, limit=MAX_CLIP_BYTES)
                    if record.scrutineer_clip_key else None)
        if download is None or download.too_large:
            raise NotFound(f"Model '{record.name}' has no scrutineering clip yet.", field="model_id")
        with download.body:
            return download.body.read()

    def doubts(self, model_ids: list[str], racer_names: RacerNames | None = None) -> list[str]:
        """Why each of these models may not drive on a car (failed, not yet or never scrutineered), to ask staff
        before sending them: a warning, never a refusal. Ids that are no AVAILABLE model are the sender's to refuse.
        racer_names names each model's racer as the page does ({sub: name} for (sub, sign-in name) pairs)."""
        found = []
        for model_id in model_ids:
            try:
                found.append(self.models.available_model(model_id))
            except (NotFound, Conflict):
                continue
        names = racer_names([(m.owner_sub, m.owner_username) for m in found]) if racer_names and found else {}
        return [doubt for m in found if (doubt := scrutiny_doubt(m, names.get(m.owner_sub)))]

    def model_files(self, record: ModelRecord, folder: Path) -> None:
        """model_metadata.json from the archive; model.onnx from the archive or, for console models, the conversion."""
        files = self.models.files
        download = files.download_bounded(record.s3_key or "", limit=self.models.max_upload_bytes)
        if download is None or download.too_large:
            raise NotFound(f"The archive of model '{record.name}' is missing.", field="model_id")
        with download.body:
            found, _ = read_tar_gz(download.body, limits=_READ_LIMITS,
                                   wanted=lambda name: name.removeprefix("./") in _MEMBERS)
        found = {name.removeprefix("./"): data for name, data in found.items()}
        if record.converted_key:
            converted = files.download_bounded(record.converted_key, limit=_READ_LIMITS.max_file_bytes)
            if converted is None or converted.too_large:
                raise NotFound(f"The ONNX conversion of model '{record.name}' is missing.", field="model_id")
            with converted.body:
                found["model.onnx"] = converted.body.read()
        for name in _MEMBERS:
            if name in found:
                (folder / name).write_bytes(found[name])

    def update(self, record: ModelRecord, *, newer_than: str = "", **changes: Any) -> ModelRecord:
        """Write `changes` onto the model while it stays AVAILABLE and its scrutineering result is still `record`'s
        (re-read and retried when another write won, so no drive's result is lost to a write from an older read).

        `newer_than` is when a background drive started: a result stored after that moment (a drive by hand) is the
        newer word, and `changes` keep it instead of writing their own."""
        for _ in range(3):
            if newer_than and record.scrutineer_result is not None and record.scrutineer_result.at > newer_than:
                changes = {name: value for name, value in changes.items() if name != "scrutineer_result"}
            updated = record.model_copy(update=changes)
            try:
                self.models.store.replace(updated, expected_status=ModelStatus.AVAILABLE, result_as_in=record)
                return updated
            except ModelChanged:
                latest = self.models.store.get(record.owner_sub, record.model_id)
                if latest is None or latest.status is not ModelStatus.AVAILABLE:
                    raise Conflict(f"Model '{record.name}' changed while it was scrutineered.") from None
                record = latest
        raise Conflict(f"Model '{record.name}' changed while it was scrutineered.")


def scrutiny_doubt(model: ModelRecord, racer: str | None = None) -> str | None:
    """One line on a model that did not pass scrutineering (None when it passed), naming its racer as `racer`
    (the page's name for them; the sign-in name when not given)."""
    status, who = model.scrutineer_status, f"{racer or model.owner_username} – {model.name}"
    result = model.scrutineer_result
    if status == "passed":
        return None
    if status == "failed":
        return f"{who}: failed scrutineering ({result.message if result else 'no details'})"
    if status == "queued":
        return f"{who}: not scrutineered yet (its test drive is queued)"
    if status == "driving":
        return f"{who}: not scrutineered yet (it is being test-driven now)"
    if status == "cannot_scrutineer":
        return f"{who}: could not be scrutineered ({model.scrutineer_status_reason})"
    return f"{who}: not scrutineered"


# --- in the background ------------------------------------------------------------------------------------------

UPCOMING_EVENT_GRACE_DAYS = 1  # an event of yesterday may still be racing (time zones, a late finish)


def upcoming_track_types(events: Iterable[Event], today: date) -> list[str]:
    """The track types a new model should be scrutineered on: those of events from yesterday on, soonest first
    (drem has no per-event racer registration, so the coming events stand for "the events the racer races at"), or
    the default track type when there is none."""
    cutoff = today - timedelta(days=UPCOMING_EVENT_GRACE_DAYS)
    upcoming = sorted((event for event in events if event.date >= cutoff), key=lambda event: event.date)
    types = list(dict.fromkeys(event.race_config.track_type.value for event in upcoming))[:MAX_TRACKS_PER_JOB]
    return types or [DEFAULT_TRACK_TYPE]


class ScrutinyEnqueuer:
    """ModelService's hook: a model that becomes AVAILABLE and drivable gets a job and is marked "queued"."""

    def __init__(self, queue: ScrutineerQueue, track_types: Callable[[], list[str]]) -> None:
        self.queue = queue
        self.track_types = track_types

    def queue_for_scrutiny(self, record: ModelRecord) -> ModelRecord:
        self.queue.enqueue(record.model_id, record.owner_sub, self.track_types())
        return record.model_copy(update={"scrutineer_state": "queued"})


class DriveOutcome(BaseModel):
    """What one bounded background drive produced: a report per track type, the clip, or why it stopped."""
    reports: list[ScrutineerResult] = []
    clip: bytes | None = None
    failure: str | None = None  # the drive was stopped (time, CPU, memory) or crashed: why, in a racer's words
    failure_detail: str | None = None  # what the simulator said, for staff


# clip_drive(model folder, track types, laps) -> DriveOutcome; the worker runs it in a bounded subprocess.
ClipDrive = Callable[[Path, list[str], int], DriveOutcome]
_VERDICT_RANK = {"invalid": 0, "cannot_scrutineer": 0, "failed": 1, "passed": 2}


def worst_result(reports: list[ScrutineerResult]) -> ScrutineerResult:
    """One result to show for several tracks: the worst verdict, its message naming every track's drive."""
    worst = min(reports, key=lambda report: _VERDICT_RANK.get(report.verdict, 0))
    if len(reports) == 1:
        return worst
    others = "; ".join(f"{r.track_type or r.track}: {r.verdict}" for r in reports if r is not worst)
    return worst.model_copy(update={"message": f"{worst.message} (also driven: {others})"})


class BackgroundScrutineer:
    """Takes one job from the queue and drives it: what the scrutineering worker does in its loop."""

    def __init__(self, scrutineer: ScrutineerService, queue: ScrutineerQueue, drive: ClipDrive, *,
                 laps: int = 2, max_clip_bytes: int = MAX_CLIP_BYTES) -> None:
        self.scrutineer = scrutineer
        self.models = scrutineer.models
        self.queue = queue
        self.drive = drive
        self.laps = laps
        self.max_clip_bytes = max_clip_bytes
        self.current: ScrutineerJob | None = None

    def run_one(self) -> ScrutineerJob | None:
        """Drive the oldest waiting job; the job (None when the queue had nothing to take)."""
        job = self.queue.take()
        if job is None:
            return None
        self.current = job  # left set if the drive is interrupted, so `give_back` knows what to return
        self._drive(job)
        self.current = None
        return job

    def _drive(self, job: ScrutineerJob) -> None:
        record = self.models.store.get(job.owner_sub, job.model_id)
        if record is None or record.status is not ModelStatus.AVAILABLE or record.scrutiny != "ready":
            self.queue.drop(job.model_id)  # deleted meanwhile, or nothing to drive: the job has no purpose
            return
        if self.queue.exhausted(job):
            reason = (f"The test drive stopped {MAX_ATTEMPTS} times without finishing, so your model was not checked. "
                      "Try “Drive again” on the model page; it can still race on a stock DeepRacer.")
            self._finish(job, record, self._result(job, "cannot_scrutineer", reason), None)
            return
        record = self._mark(record, "driving")
        started = self.models.now()
        logs.log(logging.INFO, "scrutineering", model_id=job.model_id, track_types=job.track_types,
                 attempt=job.attempts)
        with tempfile.TemporaryDirectory(prefix="scrutineer-") as folder:
            try:
                self.scrutineer.model_files(record, Path(folder))
            except (NotFound, Conflict) as error:
                outcome = DriveOutcome(failure=f"drem could not fetch your model's files for the test drive: "
                                       f"{error.message} Upload the model again.", failure_detail=error.message)
            else:
                outcome = self.drive(Path(folder), job.track_types, self.laps)
        if outcome.failure or not outcome.reports:
            result = self._result(job, "cannot_scrutineer", outcome.failure or NO_REPORT, outcome.failure_detail)
        else:
            result = worst_result([r.model_copy(update={"at": self.models.now()}) for r in outcome.reports])
        clip = outcome.clip if outcome.clip and len(outcome.clip) <= self.max_clip_bytes else None
        self._finish(job, record, result, clip, started=started)

    def _result(self, job: ScrutineerJob, verdict: str, message: str, detail: str | None = None) -> ScrutineerResult:
        return ScrutineerResult(verdict=verdict, message=message, detail=detail, track="",
                                track_type=job.track_types[0], laps=self.laps, at=self.models.now())

    def _mark(self, record: ModelRecord, state: str) -> ModelRecord:
        try:
            return self.scrutineer.update(record, scrutineer_state=state)
        except Conflict:
            return record

    def _finish(self, job: ScrutineerJob, record: ModelRecord, result: ScrutineerResult, clip: bytes | None, *,
                started: str = "") -> None:
        changes: dict[str, Any] = {"scrutineer_result": result, "scrutineer_state": None}
        record = self.models.store.get(record.owner_sub, record.model_id) or record
        if started and record.scrutineer_result is not None and record.scrutineer_result.at > started:
            clip = None  # someone drove it by hand ("drive again") while this drive ran: theirs is the newer word
        if clip is not None:
            key = scrutineer_clip_key(record.owner_sub, record.model_id)
            self.models.files.put(key, clip)
            changes["scrutineer_clip_key"] = key
        try:  # a hand drive stored between that read and this write is kept too (update's newer_than)
            self.scrutineer.update(record, newer_than=started, **changes)
        except Conflict:
            pass  # deleted while it drove: nothing left to show the result on
        self.queue.finish(job)
        logs.log(logging.INFO, "scrutineered", model_id=job.model_id, verdict=result.verdict,
                 clip_bytes=len(clip) if clip else 0)

    def give_back(self) -> None:
        """Stopping mid-drive (SIGTERM): the job goes back to the queue at once and the model says "queued"."""
        job = self.current
        if job is None:
            return
        self.queue.give_back(job)
        record = self.models.store.get(job.owner_sub, job.model_id)
        if record is not None and record.status is ModelStatus.AVAILABLE:
            self._mark(record, "queued")
