"""Training jobs of the learning booth, the model versions they make (v0001, v0002 …) and each racer's active version.

A racer queues a job from a set of their own FINALISED runs; the booth worker (local/drem_local/workers/trainer.py)
takes one job at a time, oldest first: QUEUED (with its place in the queue) → RUNNING (progress 0..1, epoch, loss) →
DONE (the model version it made) | FAILED (the reason, in words). The worker submits the archive through the same
upload validation as any racer's upload (`ModelService.submit_archive`), so a trained model lands in "my models" as
the next version and is judged exactly like one a racer uploaded. A job left RUNNING by a worker that died is queued
again when a worker starts, and after the worker lost storage midway (`requeue_interrupted`: one worker per stack,
so a RUNNING job it is not training is an interrupted one): an acknowledged job is never lost, nor left RUNNING.
Everything the job makes is keyed on it: the version's model id and name are recorded on the job before the submit
(`plan_version`), and the submit with that id is idempotent; the autonomous run's id likewise (`plan_autonomous_run`,
and the run itself carries the job's id). So a worker killed after any step finishes the same version and run when it
takes the job again, never a second copy.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from enum import StrEnum
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.core.errors import Conflict, InvalidInput, NotFound
from chalicelib.core.principals import Principal
from chalicelib.domain.booth_runs import ListRunsQuery, RecordChanged, RunMode, RunService, RunStatus, new_record_id
from chalicelib.domain.ownership import require_owner_or_role
from chalicelib.domain.racer_models import MODEL_STAFF, ModelRecord, ModelService, ModelStatus, utc_now

JOB_ID_PATTERN = r"^[a-f0-9]{12,40}$"
VERSION_NAME = re.compile(r"^v(\d{4})$")
MAX_RUNS_PER_JOB = 50
MAX_EPOCHS = 30
DEFAULT_EPOCHS = 8
NO_DRIVES = "You have no finished drive to learn from yet: drive a lap first."
JOB_WAITING = "Your training job is still in the queue or running: wait for it to finish."


class JobStatus(StrEnum):
    QUEUED = "QUEUED"
    RUNNING = "RUNNING"
    DONE = "DONE"
    FAILED = "FAILED"


class NewJob(BaseModel):
    model_config = ConfigDict(extra="forbid")
    run_ids: list[str] = Field(min_length=1, max_length=MAX_RUNS_PER_JOB, description="your FINALISED manual runs")
    epochs: int = Field(default=DEFAULT_EPOCHS, ge=1, le=MAX_EPOCHS)


class TrainingJob(BaseModel):
    model_config = ConfigDict(frozen=True)
    job_id: str
    owner_sub: str
    owner_username: str
    run_ids: list[str]
    track_id: str  # the track of the first run: where the new version's autonomous run drives
    frames: int
    epochs: int
    status: JobStatus
    created_at: str
    started_at: str | None = None
    finished_at: str | None = None
    progress: float = 0.0
    stage: str = ""  # what the worker is doing now, in words (downloading the runs, training, scrutineering …)
    epoch: int = 0
    loss: float | None = None
    model_id: str | None = None
    model_name: str | None = None
    reason: str | None = None
    autonomous_run_id: str | None = None


class JobView(BaseModel):
    """A job as its owner sees it: with its place in the queue while it waits (1 = next)."""
    job: TrainingJob
    queue_position: int | None = None

    def public(self) -> dict[str, Any]:
        return {**self.job.model_dump(mode="json"), "queue_position": self.queue_position}


class JobStore(Protocol):
    def create_job(self, job: TrainingJob) -> None: ...
    def replace_job(self, job: TrainingJob, *, expected_status: str) -> None: ...
    def get_job(self, job_id: str) -> TrainingJob | None: ...
    def jobs_of(self, owner_sub: str) -> list[TrainingJob]: ...
    def all_jobs(self) -> list[TrainingJob]: ...
    def set_active(self, owner_sub: str, model_id: str) -> None: ...
    def active_of(self, owner_sub: str) -> str | None: ...


class TrainingService:
    def __init__(self, store: JobStore, runs: RunService, models: ModelService, *,
                 clock: Callable[[], str] = utc_now, new_id: Callable[[], str] = new_record_id) -> None:
        self.store = store
        self.runs = runs
        self.models = models
        self._clock = clock
        self._new_id = new_id

    # -- racers ------------------------------------------------------------------------------------------------------

    def create(self, principal: Principal, request: NewJob) -> JobView:
        sub, username = principal.sub or "", getattr(principal, "username", "") or ""
        if not principal.is_user or not sub:
            raise InvalidInput("Only signed-in users train models.")
        runs = [self.runs.get(principal, run_id) for run_id in dict.fromkeys(request.run_ids)]
        for run in runs:
            if run.owner_sub != sub:
                raise InvalidInput(f"Run {run.run_id} is not yours: you train only on your own runs.",
                                   field="run_ids")
            if run.status is not RunStatus.FINALISED or run.mode is not RunMode.MANUAL or run.metrics is None:
                raise InvalidInput(f"Run {run.run_id} is not a finished manual run ({run.status.value}).",
                                   field="run_ids")
        refused = self._waiting(sub) or self._unchanged_since(sub, [r.run_id for r in runs], request.epochs)
        if refused:
            raise Conflict(refused, field="run_ids")
        job = TrainingJob(job_id=self._new_id(), owner_sub=sub, owner_username=username,
                          run_ids=[r.run_id for r in runs], track_id=runs[0].track_id,
                          frames=sum(r.metrics.frames for r in runs if r.metrics), epochs=request.epochs,
                          status=JobStatus.QUEUED, created_at=self._clock())
        self.store.create_job(job)
        return self._view(job)

    def train_on_my_runs(self, principal: Principal, *, epochs: int) -> JobView:
        """The booth's Train button: every finished manual run of the caller (the newest 50)."""
        ids = self.drives_to_train(principal)
        if not ids:
            raise InvalidInput(NO_DRIVES, field="run_ids")
        return self.create(principal, NewJob(run_ids=ids, epochs=epochs))

    def why_not_train(self, principal: Principal, *, epochs: int = DEFAULT_EPOCHS,
                      drives: list[str] | None = None) -> str | None:
        """Why the Train button is off for training on all the caller's drives (`drives_to_train`, if the caller has
        not just read them) with these epochs, in words (None: it is on). The same reasons `create` refuses with, so
        the page and the API never disagree."""
        ids = self.drives_to_train(principal) if drives is None else drives
        if not ids:
            return NO_DRIVES
        return self._waiting(principal.sub or "") or self._unchanged_since(principal.sub or "", ids, epochs)

    def drives_to_train(self, principal: Principal) -> list[str]:
        """What Train learns from: the caller's finished manual runs, the newest 50."""
        runs = self.runs.list_runs(principal, ListRunsQuery())
        return [r.run_id for r in runs if r.owner_sub == principal.sub and r.mode is RunMode.MANUAL
                and r.status is RunStatus.FINALISED][:MAX_RUNS_PER_JOB]

    def _waiting(self, owner_sub: str) -> str | None:
        busy = any(j.status in (JobStatus.QUEUED, JobStatus.RUNNING) for j in self.store.jobs_of(owner_sub))
        return JOB_WAITING if busy else None

    def _unchanged_since(self, owner_sub: str, run_ids: list[str], epochs: int) -> str | None:
        """Nothing changed: a version the racer still has learned from exactly these drives with these settings.
        Training is seeded (local/drem_local/workers/trainer.py: seed 0, one thread), so it would make that model
        file again, and the upload check refuses an identical file while the earlier one is AVAILABLE — after the
        whole training (~170 s). A deleted version does not count: its copy would be accepted."""
        same = [j for j in self.store.jobs_of(owner_sub) if j.status is JobStatus.DONE and j.model_id
                and set(j.run_ids) == set(run_ids) and j.epochs == epochs]
        for job in sorted(same, key=lambda j: (j.finished_at or "", j.created_at), reverse=True):
            model = self.models.store.get(owner_sub, job.model_id or "")
            if model is not None and model.status is ModelStatus.AVAILABLE:
                drives = "this same drive" if len(run_ids) == 1 else f"these same {len(run_ids)} drives"
                return (f"Nothing changed since {model.name}: it learned from {drives} with {_epochs(epochs)}. "
                        "Drive again, or change the epochs, to give the next version something new.")
        return None

    def list_jobs(self, principal: Principal, *, everyone: bool = False) -> list[JobView]:
        jobs = self.store.all_jobs() if everyone and principal.roles & MODEL_STAFF else \
            self.store.jobs_of(principal.sub or "")
        queue = self._queue()
        return [JobView(job=j, queue_position=_position(queue, j)) for j in jobs]

    def get(self, principal: Principal, job_id: str) -> JobView:
        job = self.store.get_job(job_id) if re.fullmatch(JOB_ID_PATTERN, job_id or "") else None
        if job is None:
            raise NotFound(f"There is no training job {job_id[:40]!r}.", field="job_id")
        require_owner_or_role(principal, job.owner_sub, MODEL_STAFF)
        return self._view(job)

    def set_active(self, principal: Principal, model_id: str) -> ModelRecord:
        model = self.models.get(principal, model_id)
        if model.owner_sub != principal.sub:
            raise InvalidInput("You mark one of your own model versions active.", field="model_id")
        if model.status is not ModelStatus.AVAILABLE:
            raise Conflict(f"Model '{model.name}' is {model.status.value}; only an AVAILABLE model can be active.",
                           field="model_id")
        self.store.set_active(model.owner_sub, model.model_id)
        return model

    def active_of(self, owner_sub: str) -> str | None:
        return self.store.active_of(owner_sub)

    # -- the worker --------------------------------------------------------------------------------------------------

    def claim_next(self) -> TrainingJob | None:
        """The oldest QUEUED job, now RUNNING (None when the queue is empty); a job another worker took is skipped."""
        for job in self._queue():
            running = job.model_copy(update={"status": JobStatus.RUNNING, "started_at": self._clock()})
            try:
                self.store.replace_job(running, expected_status=JobStatus.QUEUED.value)
            except RecordChanged:
                # Our own claim, stored before storage went away, whose retry found it RUNNING: still ours (the
                # started_at is the one we wrote). Skipping it would leave it RUNNING with nobody training it.
                stored = self.store.get_job(job.job_id)
                if stored is not None and stored.status is JobStatus.RUNNING and \
                        stored.started_at == running.started_at:
                    return stored
                continue
            return running
        return None

    def requeue_interrupted(self) -> list[TrainingJob]:
        """Jobs left RUNNING by a worker that died: queued again (progress reset), in their original order. The
        version and autonomous run the job had recorded stay on it, so taking it again finishes those."""
        requeued = []
        for job in self.store.all_jobs():
            if job.status is JobStatus.RUNNING:
                again = job.model_copy(update={"status": JobStatus.QUEUED, "progress": 0.0, "epoch": 0, "loss": None,
                                               "stage": ""})
                try:
                    self.store.replace_job(again, expected_status=JobStatus.RUNNING.value)
                    requeued.append(again)
                except RecordChanged:
                    continue
        return requeued

    def plan_version(self, job: TrainingJob, model_id: str, model_name: str) -> TrainingJob:
        """Record on the job the model version it is about to submit (its id and name), before the submit: a worker
        killed after the submit finds that version on the job when it takes the job again, and finishes it instead
        of training and submitting a second copy (which the duplicate check would refuse, failing the job)."""
        planned = job.model_copy(update={"model_id": model_id, "model_name": model_name})
        self.store.replace_job(planned, expected_status=JobStatus.RUNNING.value)
        return planned

    def plan_autonomous_run(self, job: TrainingJob, run_id: str) -> TrainingJob:
        """Record the autonomous run made for the job's version, so a restarted worker drives that one again."""
        planned = job.model_copy(update={"autonomous_run_id": run_id})
        self.store.replace_job(planned, expected_status=JobStatus.RUNNING.value)
        return planned

    def report(self, job: TrainingJob, *, progress: float, epoch: int, loss: float | None,
               stage: str = "training") -> TrainingJob:
        updated = job.model_copy(update={"progress": round(max(0.0, min(1.0, progress)), 4), "epoch": epoch,
                                         "loss": None if loss is None else round(loss, 6), "stage": stage})
        self.store.replace_job(updated, expected_status=JobStatus.RUNNING.value)
        return updated

    def finish(self, job: TrainingJob, model: ModelRecord, autonomous_run_id: str | None = None) -> TrainingJob:
        done = job.model_copy(update={"status": JobStatus.DONE, "progress": 1.0, "stage": "",
                                      "finished_at": self._clock(),
                                      "model_id": model.model_id, "model_name": model.name,
                                      "autonomous_run_id": autonomous_run_id})
        self.store.replace_job(done, expected_status=JobStatus.RUNNING.value)
        return done

    def fail(self, job: TrainingJob, reason: str) -> TrainingJob:
        failed = job.model_copy(update={"status": JobStatus.FAILED, "finished_at": self._clock(),
                                        "reason": reason[:500]})
        self.store.replace_job(failed, expected_status=JobStatus.RUNNING.value)
        return failed

    def next_version_name(self, owner_sub: str) -> str:
        """v0001 for a racer's first trained model, then one more than the highest version they ever had."""
        highest, token = 0, None
        while True:
            page = self.models.store.list_owner(owner_sub, limit=100, next_token=token, include_deleted=True)
            for model in page.models:
                match = VERSION_NAME.match(model.name)
                if match:
                    highest = max(highest, int(match.group(1)))
            token = page.next_token
            if not token:
                return f"v{highest + 1:04d}"

    # -- plumbing ----------------------------------------------------------------------------------------------------

    def _queue(self) -> list[TrainingJob]:
        return sorted((j for j in self.store.all_jobs() if j.status is JobStatus.QUEUED),
                      key=lambda j: (j.created_at, j.job_id))

    def _view(self, job: TrainingJob) -> JobView:
        return JobView(job=job, queue_position=_position(self._queue(), job))


def _epochs(epochs: int) -> str:
    return f"{epochs} epoch{'s' if epochs != 1 else ''}"


def _position(queue: list[TrainingJob], job: TrainingJob) -> int | None:
    if job.status is not JobStatus.QUEUED:
        return None
    ids = [j.job_id for j in queue]
    return ids.index(job.job_id) + 1 if job.job_id in ids else None
