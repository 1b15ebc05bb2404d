"""The check of an arrived model upload, run by the background worker instead of the app's request threads.

Checking a console archive is CPU work: reading 20+ MB from storage and hashing it, gunzip and a tar walk, parsing
the protobuf graph, unpacking it again for the ONNX conversion, copying it. In the local stack one app process serves
every page through its request threads, so that work beside them (the GIL, two cores) slowed the public board while
racers uploaded. Where a worker runs (`drem up` always starts the scrutineering worker; the setting
`model_checks_in_worker`), the app only records that the check is wanted, a job in a queue, and waits for the verdict
without using the CPU; the worker (drem_local.workers.scrutineer, at the lowest CPU priority) takes the job and runs
`ModelService.finish_check`, the one owner of the check, exactly as the app did. On AWS nothing changes: the checking
Lambda (the upload-complete event, or the API's own `/complete`) is a process of its own, not the board's.

Durability: the job is written before the app waits, so a kill -9 of the app leaves the check to the worker; a check
cut short in the worker keeps its job leased until the lease ends (then it is taken again) and its record says a check
started (`ModelService.resume_checks` redoes it once stale), whichever comes first. If no worker takes the job within
`takeover_s` (the worker is down or restarting), the app takes the job itself and checks in its own process, as
before, rather than leave the racer waiting.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Literal

from chalicelib import logs
from chalicelib.core.errors import Conflict, NotFound
from chalicelib.domain.racer_models import ModelRecord, ModelService, ModelStatus
from chalicelib.domain.scrutineer_queue import ScrutineerQueue

# The queue's jobs name the tracks a drive is for; a check has none, so its jobs carry this word instead.
CHECK_JOB = "upload-check"
# Most checks end within seconds; a racer's `/complete` waits this long for the verdict, then answers the model as it
# stands ("Checking…": the console conversion alone may take 60 s), before clients' request timeouts (the CLI's is
# 30 s), and the page or `drem models upload` reads the model again until its check ends.
WAIT_S = 25.0
TAKEOVER_S = 10.0
POLL_S = 0.2


class WorkerChecks:
    """A CheckRunner (chalicelib.domain.racer_models) over a queue that the background worker takes from."""

    def __init__(self, queue: ScrutineerQueue, *, wait_s: float = WAIT_S, takeover_s: float = TAKEOVER_S,
                 poll_s: float = POLL_S, sleep: Callable[[float], None] = time.sleep,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.queue = queue
        self.wait_s = wait_s
        self.takeover_s = takeover_s
        self.poll_s = poll_s
        self._sleep = sleep
        self._clock = clock

    def request(self, models: ModelService, record: ModelRecord) -> ModelRecord:
        """App side: queue the check (once per model) and wait for its verdict, reading the record (no CPU work)."""
        self.queue.enqueue(record.model_id, record.owner_sub, [CHECK_JOB])
        started = self._clock()
        while True:
            latest = models.reread(record)
            if latest.status is not ModelStatus.UPLOADED:
                return latest
            waited = self._clock() - started
            if waited >= self.takeover_s:
                job = self.queue.take_this(record.model_id)
                if job is not None:  # no worker took it: check it here rather than leave the racer waiting
                    logs.log(logging.WARNING, "no worker took the model check; checking it in the app",
                             model_id=record.model_id, waited_s=round(waited, 1))
                    checked = models.finish_check(latest)
                    self.queue.finish(job)
                    return checked
            if waited >= self.wait_s:
                return latest
            self._sleep(self.poll_s)

    def run_one(self, models: ModelService) -> ModelRecord | None | Literal[False]:
        """Worker side: check the oldest requested upload. Its record as it then stands (a model deleted or judged
        meanwhile is left as it is); None if the record or its file is gone; False when no check was waiting. An
        error from storage leaves the job leased: it is taken again when the lease ends (or resumed once stale)."""
        job = self.queue.take()
        if job is None:
            return False
        record = models.store.get(job.owner_sub, job.model_id)
        try:
            checked = models.finish_check(record) if record is not None else None
        except (Conflict, NotFound):  # deleted meanwhile, or its file is gone: nothing left to check
            checked = None
        self.queue.finish(job)
        return checked
