"""Taking a racer's upload for the league: the files they have, packed as one .tar.gz by `drem league push`, read
and assembled here on the server (never on the racer's machine, whose JSON could say anything).

The upload is hostile input: it is read in memory with the bounds of chalicelib.formats.league_export (member count,
decompressed bytes, size of each file read; unsafe names and links skipped), then assembled
(chalicelib.domain.league_assembler: every missing file is named with where the racer's tool writes it) and
checked by LeagueService.push like every submission.

With `model_id` (a model the racer uploaded: a console archive, driven through its ONNX conversion, or a drem ONNX
model) the entry is *pending*: it is queued for drem's re-drive on the board's track (`LeagueVerifier`, in the
scrutineering worker), which ranks what drem measured. The model's own model_metadata.json stands in when the logs
download has none.
"""
from __future__ import annotations

import io
import logging
import tempfile
from collections.abc import Callable
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field

from chalicelib import logs
from chalicelib.core.errors import Conflict, Forbidden, NotFound, PayloadTooLarge
from chalicelib.core.principals import Principal
from chalicelib.domain.league import NAME_PATTERN, LeagueService, Submission, VerifiedDrive
from chalicelib.domain.league_assembler import assemble
from chalicelib.domain.model_scrutiny import DriveOutcome, ScrutineerService
from chalicelib.domain.racer_models import ModelRecord, ModelStatus, ScrutineerResult
from chalicelib.domain.scrutineer_queue import MAX_ATTEMPTS, ScrutineerJob, ScrutineerQueue
from chalicelib.formats.league_export import ExportFiles, ExportLimits, MiB, read_tar_gz

# An upload holds logs, metrics and evaluation sim-traces (no model graph, no checkpoints, no training sim-traces:
# the CLI leaves those out); API Gateway takes at most 10 MB per request.
MAX_UPLOAD_BYTES = 9 * MiB
UPLOAD_LIMITS = ExportLimits(max_archive_bytes=MAX_UPLOAD_BYTES, max_expanded_bytes=96 * MiB, max_members=5_000,
                             max_file_bytes=32 * MiB, max_total_read_bytes=96 * MiB)
# JSON is accepted only to be answered: who may call is checked first (401/403), then the body is refused as "not a
# .tar.gz": the server takes no ready-made submissions.
UPLOAD_CONTENT_TYPES = ["application/gzip", "application/x-gzip", "application/octet-stream", "application/json"]


class PushOptions(BaseModel):
    model_config = ConfigDict(extra="forbid")
    racer: str | None = Field(default=None, pattern=NAME_PATTERN,
                              description="push for this racer (admins only; default: yourself)")
    model_name: str | None = Field(default=None, pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,79}$",
                                   description="the name shown on the board (default: the export's name)")
    model_id: str | None = Field(default=None, pattern=r"^[A-Za-z0-9_-]{1,64}$",
                                 description="your uploaded model: drem re-drives it and ranks what it measures")


class LeagueIntake:
    def __init__(self, league: LeagueService, scrutineer: ScrutineerService | None = None,
                 verify_queue: ScrutineerQueue | None = None) -> None:
        self.league = league
        self.scrutineer = scrutineer
        self.verify_queue = verify_queue

    def push_upload(self, principal: Principal, track: str, upload: bytes, options: PushOptions) -> Submission:
        racer = self.league.pusher(principal, options.racer)
        length_m = self.league.track_length_m(track)  # an unknown track is refused before the upload is read
        if len(upload) > MAX_UPLOAD_BYTES:
            raise PayloadTooLarge(f"the upload is larger than {MAX_UPLOAD_BYTES // MiB} MiB; push the logs, metrics "
                                  "and evaluation sim-traces only (drem league push packs just those)", field="body")
        files, names = read_tar_gz(io.BytesIO(upload), limits=UPLOAD_LIMITS)
        model = self._model(principal, racer, options.model_id) if options.model_id else None
        if model is not None and not any(name.endswith("model_metadata.json") for name in files):
            files["model_metadata.json"] = self._model_metadata(model)
            names.append("model_metadata.json")
        export = ExportFiles(options.model_name or "model", files, names)
        body = assemble(export, racer=racer, track=track, track_length_m=length_m, model_name=options.model_name)
        if model is not None:
            body = body.model_copy(update={"model_id": model.model_id})
        submission = self.league.push(principal, track, body)
        if model is not None and self.verify_queue is not None:
            self.verify_queue.drop(model.model_id)  # a drive waiting for an older push of this model: this one wins
            self.verify_queue.enqueue(model.model_id, model.owner_sub, [track])
        return submission

    def _model(self, principal: Principal, racer: str, model_id: str) -> ModelRecord:
        """The racer's own model, ready to drive (console archives through their ONNX conversion)."""
        if self.scrutineer is None or self.verify_queue is None:
            raise Conflict("This drem server cannot re-drive models (no scrutineering worker): push the logs alone.",
                           field="model_id")
        record = self.scrutineer.models.get(principal, model_id)  # owner or model staff; others get 404/403
        if record.owner_username != racer:
            raise Forbidden(f"Model '{record.name}' belongs to {record.owner_username}, not to {racer}.",
                            field="model_id")
        if record.status is not ModelStatus.AVAILABLE or record.scrutiny != "ready":
            reason = record.scrutiny_reason or f"it is {record.status.value}"
            raise Conflict(f"Model '{record.name}' cannot be re-driven by drem ({reason}); push the logs alone "
                           "(drem league push --self-reported) to enter them as self-reported.", field="model_id")
        return record

    def _model_metadata(self, record: ModelRecord) -> bytes:
        assert self.scrutineer is not None
        with tempfile.TemporaryDirectory(prefix="league-model-") as folder:
            self.scrutineer.model_files(record, Path(folder))
            path = Path(folder) / "model_metadata.json"
            return path.read_bytes() if path.is_file() else b""


# drive(model folder with model_metadata.json + model.onnx, track name, laps) -> DriveOutcome (one report)
TrackDrive = Callable[[Path, str, int], DriveOutcome]
VERIFY_LAPS = 3


class LeagueVerifier:
    """Takes one league job (a model and the board's track) and re-drives it: what the scrutineering worker does
    when no scrutineering job waits."""

    def __init__(self, league: LeagueService, scrutineer: ScrutineerService, queue: ScrutineerQueue,
                 drive: TrackDrive, *, laps: int = VERIFY_LAPS) -> None:
        self.league = league
        self.scrutineer = scrutineer
        self.queue = queue
        self.drive = drive
        self.laps = laps
        self.current: ScrutineerJob | None = None  # left set if the drive is interrupted, for `give_back`

    def give_back(self) -> None:
        """Stopping mid-drive (SIGTERM): the job goes back to the queue at once, not after its lease."""
        if self.current is not None:
            self.queue.give_back(self.current)
            self.current = None

    def run_one(self) -> Submission | None | bool:
        """Re-drive the oldest waiting job: its updated submission, None if the job had nothing left to verify,
        False when the queue was empty."""
        job = self.queue.take()
        if job is None:
            return False
        self.current = job
        updated = self._verify(job)
        self.current = None
        return updated

    def _verify(self, job: ScrutineerJob) -> Submission | None:
        track = job.track_types[0]
        record = self.scrutineer.models.store.get(job.owner_sub, job.model_id)
        if record is None:
            self.queue.drop(job.model_id)
            return None
        gone = record.status is not ModelStatus.AVAILABLE
        if gone or self.queue.exhausted(job):  # the entry stays self-reported, saying why
            self.queue.drop(job.model_id)
            why = ("the model was deleted before drem re-drove it" if gone
                   else f"the re-drive stopped {MAX_ATTEMPTS} times without finishing")
            return self.league.record_drive(track, record.owner_username, job.model_id, None, why)
        with tempfile.TemporaryDirectory(prefix="league-verify-") as folder:
            try:
                self.scrutineer.model_files(record, Path(folder))
            except (NotFound, Conflict) as error:
                outcome = DriveOutcome(failure=f"drem could not fetch the model's files: {error.message}")
            else:
                outcome = self.drive(Path(folder), track, self.laps)
        report = outcome.reports[0] if outcome.reports else None
        drive = None
        if report is not None and report.verdict in ("passed", "failed"):
            drive = VerifiedDrive(laps=redrive_attempts(report), laps_completed=report.laps_completed,
                                  best_lap_s=report.best_lap_time_s, mean_lap_s=report.mean_lap_time_s,
                                  offtrack_count=report.offtrack_count, completion_pct=redrive_completion(report),
                                  message=report.message[:500], at=self.league.now())
        failure = outcome.failure or (report.message if report is not None else "no report")
        updated = self.league.record_drive(track, record.owner_username, record.model_id, drive, failure)
        self.queue.finish(job)
        logs.log(logging.INFO, "league entry re-driven", model_id=record.model_id, track=track,
                 verification=updated.verification if updated else None)
        return updated


def redrive_attempts(report: ScrutineerResult) -> int:
    """The re-drive's trials: the lap attempts that ended (the laps asked for, from a report that predates them)."""
    return report.attempts if report.attempts is not None else report.laps


def redrive_completion(report: ScrutineerResult) -> float:
    """The re-drive's completion as scrutineering measured it (mean progress per lap attempt, by the whole-lap rule
    of drem_leaderboard.laps), the measure a self-reported trial's completion is in too. Only a report that predates
    it falls back on the share of laps completed."""
    if report.completion_pct is not None:
        return report.completion_pct
    return 100.0 * report.laps_completed / max(report.laps, 1)
