"""The scrutineering queue: models waiting for their background test drive, and the lease a worker holds on one.

A model that becomes AVAILABLE and can be driven is *enqueued* (one job per model: enqueuing again changes nothing).
A worker *takes* the oldest job it can: a queued one, or one whose lease expired because the worker driving it died
(kill -9, power cut). Taking is a conditional write, so two workers never drive the same job at once; the lease is
longer than the drive's own wall-clock bound, so a live worker never loses its job. A job taken MAX_ATTEMPTS times
without finishing is given up: its model is marked "could not scrutineer" with the reason, never retried forever.
"""
from __future__ import annotations

import secrets
from collections.abc import Callable
from typing import Literal, Protocol

from pydantic import BaseModel, ConfigDict, Field

JobState = Literal["queued", "driving"]
MAX_ATTEMPTS = 3
DEFAULT_LEASE_MS = 5 * 60 * 1000  # well above the drive's wall-clock bound (ScrutineerLimits.wall_seconds)
MAX_TRACKS_PER_JOB = 3


class ScrutineerJob(BaseModel):
    model_config = ConfigDict(frozen=True)
    model_id: str
    owner_sub: str
    track_types: list[str] = Field(min_length=1, max_length=MAX_TRACKS_PER_JOB)
    enqueued_at_ms: int
    state: JobState = "queued"
    attempts: int = 0
    lease_until_ms: int = 0
    lease_token: str | None = None

    def takeable(self, now_ms: int) -> bool:
        return self.state == "queued" or self.lease_until_ms <= now_ms


class JobStore(Protocol):
    def add(self, job: ScrutineerJob) -> bool: ...  # False when the model already has a job
    def get(self, model_id: str) -> ScrutineerJob | None: ...
    def waiting(self, limit: int) -> list[ScrutineerJob]: ...  # oldest first
    def lease(self, job: ScrutineerJob, *, token: str, until_ms: int, now_ms: int) -> bool: ...
    def requeue(self, model_id: str, *, token: str) -> bool: ...
    def remove(self, model_id: str, *, token: str | None) -> bool: ...  # token None: whatever its lease


class ScrutineerQueue:
    def __init__(self, store: JobStore, clock_ms: Callable[[], int], *, lease_ms: int = DEFAULT_LEASE_MS,
                 new_token: Callable[[], str] = lambda: secrets.token_hex(8)) -> None:
        self.store = store
        self.clock_ms = clock_ms
        self.lease_ms = lease_ms
        self._new_token = new_token

    def enqueue(self, model_id: str, owner_sub: str, track_types: list[str]) -> bool:
        """Queue a model for its test drive; True if queued now, False if it already had a job (idempotent)."""
        tracks = list(dict.fromkeys(track_types))[:MAX_TRACKS_PER_JOB]
        job = ScrutineerJob(model_id=model_id, owner_sub=owner_sub, track_types=tracks,
                            enqueued_at_ms=self.clock_ms())
        return self.store.add(job)

    def take(self, *, scan: int = 50) -> ScrutineerJob | None:
        """Lease the oldest takeable job (None when there is none). A job that has used up its attempts is returned
        with `attempts >= MAX_ATTEMPTS` so the caller can give it up (see `exhausted`)."""
        now = self.clock_ms()
        for job in self.store.waiting(scan):
            if not job.takeable(now):
                continue
            token = self._new_token()
            until = now + self.lease_ms
            if self.store.lease(job, token=token, until_ms=until, now_ms=now):
                return job.model_copy(update={"state": "driving", "attempts": job.attempts + 1,
                                              "lease_until_ms": until, "lease_token": token})
        return None

    @staticmethod
    def exhausted(job: ScrutineerJob) -> bool:
        """Taken more often than a drive may crash its worker: give it up instead of driving it again."""
        return job.attempts > MAX_ATTEMPTS

    def finish(self, job: ScrutineerJob) -> bool:
        """The drive is over (result stored): the job leaves the queue if we still hold its lease."""
        return self.store.remove(job.model_id, token=job.lease_token)

    def give_back(self, job: ScrutineerJob) -> bool:
        """The worker is stopping (SIGTERM): the job is queued again at once rather than after its lease."""
        return self.store.requeue(job.model_id, token=job.lease_token or "")

    def drop(self, model_id: str) -> bool:
        """The model went away (deleted) or cannot be driven: forget its job whoever holds it."""
        return self.store.remove(model_id, token=None)

    def state_of(self, model_id: str) -> ScrutineerJob | None:
        return self.store.get(model_id)
