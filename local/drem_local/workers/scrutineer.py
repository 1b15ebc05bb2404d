"""The scrutineering worker: `drem up` runs it beside the app server; it test-drives queued models one at a time.

    python -m drem_local.workers.scrutineer [--poll-s 1.0] [--once]

It reads the same environment as the app (tables, buckets, storage endpoint) and takes one job at a time from the
queue (chalicelib.domain.scrutineer_queue). The drive itself runs in a child process (drem_local.workers.
scrutineer_drive) bounded like the console-model converter: a wall-clock limit, a CPU-time limit and an address-space
limit, one onnxruntime/OpenMP thread, and the lowest priority (nice, and SCHED_IDLE on Linux), so a rush of uploads
queues up here instead of competing with the live pages for the CPU. A racer's graph that loops, balloons or crashes
costs that child only and the model says "could not scrutineer" with the reason. On SIGTERM the running drive is
stopped and its job goes back to the queue; after kill -9 the job's lease expires and another start of the worker
drives it again.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drem_local.app_source import use_app_source
from drem_sim.learn import scrutiny_words
from drem_sim.learn.scrutiny_words import GiB, PlainFailure

DRIVE_MODULE = "drem_local.workers.scrutineer_drive"
NICENESS = 10  # chalicelib.contained.BACKGROUND_NICENESS (chalicelib is importable only after use_app_source)
_PR_SET_PDEATHSIG = 1
LEASE_VARIABLE = "DREM_SCRUTINEER_LEASE_S"  # how long a taken job is the worker's (default 5 minutes)
# How often the worker looks for model checks a crash cut short (uploads left UPLOADED); see resume_model_checks.
RESUME_CHECKS_EVERY_S = float(os.environ.get("DREM_RESUME_CHECKS_EVERY_S", "30"))


@dataclass(frozen=True)
class ScrutineerLimits:
    wall_seconds: float = 90.0
    cpu_seconds: int = 90
    memory_bytes: int = 3 * GiB  # address space: onnxruntime and OpenCV map more than they touch
    niceness: int = NICENESS


class BoundedClipDrive:
    """`ClipDrive` (chalicelib.domain.model_scrutiny) in a contained child process."""

    def __init__(self, limits: ScrutineerLimits | None = None, *, python: str = sys.executable) -> None:
        self.limits = limits or ScrutineerLimits()
        self.python = python
        self.process: subprocess.Popen[bytes] | None = None

    def __call__(self, folder: Path, track_types: list[str], laps: int, *, track: str | None = None) -> Any:
        from chalicelib.domain.model_scrutiny import DriveOutcome

        limits = self.limits
        clip = folder / "clip.gif"
        where = ["--track", track] if track else [arg for kind in track_types for arg in ("--track-type", kind)]
        command = [self.python, "-m", DRIVE_MODULE, "--folder", str(folder), "--laps", str(laps),
                   "--clip", str(clip), *where]
        environment = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1",
                       "DREM_SIM_THREADS": "1"}
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=environment,
                                   cwd=folder, start_new_session=True, preexec_fn=_limit(limits))
        self.process = process
        try:
            stdout, stderr = process.communicate(timeout=limits.wall_seconds)
        except subprocess.TimeoutExpired:
            self.stop()
            process.communicate()
            return _failed(scrutiny_words.drive_timed_out(limits.wall_seconds))
        except BaseException:  # SIGTERM while it drives: the drive stops with the worker
            self.stop()
            raise
        finally:
            self.process = None
        if process.returncode != 0:
            return _failed(_crash_reason(process.returncode, stderr, limits))
        try:
            answer = json.loads(stdout.decode("utf-8", "replace").strip().splitlines()[-1])
            outcome = DriveOutcome.model_validate({"reports": answer["reports"]})
        except (ValueError, KeyError, IndexError):
            return _failed(scrutiny_words.no_answer(stderr.decode("utf-8", "replace")))
        if clip.is_file():
            outcome = outcome.model_copy(update={"clip": clip.read_bytes()})
        return outcome

    def stop(self) -> None:
        from chalicelib.contained import kill_group

        process = self.process
        if process is not None:
            kill_group(process)


def _limit(limits: ScrutineerLimits) -> Callable[[], None]:  # a preexec_fn: runs in the child before exec
    # imported here, in the parent: the child only calls them
    from chalicelib.contained import limit_resources, lowest_priority

    def apply() -> None:
        import ctypes

        try:  # the drive dies with its worker (a kill -9 of the worker must not leave a drive running unwatched)
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
        except (OSError, AttributeError):
            pass
        lowest_priority(limits.niceness)
        limit_resources(limits.memory_bytes, limits.cpu_seconds)
    return apply


def _failed(failure: PlainFailure) -> Any:
    from chalicelib.domain.model_scrutiny import DriveOutcome

    return DriveOutcome(failure=failure.message, failure_detail=failure.detail)


def _crash_reason(returncode: int, stderr: bytes, limits: ScrutineerLimits) -> PlainFailure:
    """Why the drive's child died, in a racer's words (and the child's own last lines for staff)."""
    from chalicelib.contained import child_death

    death = child_death(returncode, stderr)
    if death.cause == "cpu":
        return scrutiny_words.drive_out_of_cpu(limits.cpu_seconds)
    if death.cause == "signal":
        return scrutiny_words.simulator_crashed(f"killed by {death.how}", death.stderr)
    if death.cause == "memory":
        return scrutiny_words.drive_out_of_memory(limits.memory_bytes, death.stderr)
    return scrutiny_words.simulator_crashed(death.how, death.stderr)


class _Stop(BaseException):
    """SIGTERM/SIGINT. A BaseException, like KeyboardInterrupt: botocore retries whatever `Exception` breaks a
    request, so an Exception raised while the worker waits on storage would be swallowed and the worker never stop."""


def _raise_stop(_signum: int, _frame: object) -> None:
    raise _Stop()


def background_scrutineer(drive: Any) -> Any:
    from chalicelib import services
    from chalicelib.domain.model_scrutiny import BackgroundScrutineer

    queue = services.scrutineer_queue()
    if os.environ.get(LEASE_VARIABLE):  # tests and benches that kill workers on purpose wait less for the lease
        queue.lease_ms = int(float(os.environ[LEASE_VARIABLE]) * 1000)
    return BackgroundScrutineer(services.scrutineer_service(), queue, drive)


def resume_model_checks() -> None:
    """Finish model checks a crash cut short (ModelService.resume_checks): uploads never stay "Checking…"."""
    from chalicelib import logs, services

    service = services.model_service()
    if os.environ.get("DREM_CHECK_STALE_AFTER_S"):  # tests that kill the app mid-check wait less
        service.check_stale_after_s = float(os.environ["DREM_CHECK_STALE_AFTER_S"])
    try:
        for record in service.resume_checks():
            logs.log(logging.INFO, "model check resumed and finished", model_id=record.model_id,
                     status=record.status.value)
    except Exception as error:  # storage briefly away (restarting): the next round tries again
        logs.log(logging.WARNING, "interrupted model checks could not be resumed yet", error=repr(error)[:300])


def league_verifier(drive: BoundedClipDrive) -> Any:
    """The league's re-drives, taken when no scrutineering job waits; None where the server has no such queue."""
    from chalicelib import services
    from chalicelib.domain.league_intake import LeagueVerifier

    queue = services.league_verify_queue()
    if queue is None:
        return None
    if os.environ.get(LEASE_VARIABLE):
        queue.lease_ms = int(float(os.environ[LEASE_VARIABLE]) * 1000)
    return LeagueVerifier(services.league_service(), services.scrutineer_service(), queue,
                          lambda folder, track, laps: drive(folder, [], laps, track=track))


def _resume_checks_forever() -> None:
    while True:
        resume_model_checks()
        time.sleep(RESUME_CHECKS_EVERY_S)


def serve(poll_s: float, once: bool = False) -> int:
    use_app_source()
    from chalicelib import logs
    from chalicelib.contained import lowest_priority

    lowest_priority(NICENESS)
    drive = BoundedClipDrive()
    worker = background_scrutineer(drive)
    league = league_verifier(drive)
    signal.signal(signal.SIGTERM, _raise_stop)
    signal.signal(signal.SIGINT, _raise_stop)
    logs.log(logging.INFO, "scrutineering worker started", pid=os.getpid())
    # Beside the drives, not between them: a drive takes up to 90 s, and a check cut short must not wait for a queue.
    threading.Thread(target=_resume_checks_forever, name="resume-model-checks", daemon=True).start()
    try:
        while True:
            try:
                job = worker.run_one()
                if job is None and league is not None and league.run_one() is not False:
                    job = "league"  # a league re-drive ran: look at both queues again at once
            except Exception as error:  # storage briefly away (restarting): wait and take the queue again
                logs.log(logging.WARNING, "scrutineering worker could not take a job", error=repr(error)[:300])
                job = None
                time.sleep(poll_s * 3)
            if once and job is None:
                return 0
            if job is None:
                time.sleep(poll_s)
    except _Stop:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        drive.stop()
        try:
            worker.give_back()
            if league is not None:
                league.give_back()
        except Exception as error:  # the lease then expires and the job is driven after the next start
            logs.log(logging.WARNING, "scrutineering job not given back", error=repr(error)[:300])
        logs.log(logging.INFO, "scrutineering worker stopped")
        return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drem_local.workers.scrutineer", description=__doc__.split("\n")[0])
    parser.add_argument("--poll-s", type=float, default=1.0, help="how often an idle worker looks at the queue")
    parser.add_argument("--once", action="store_true", help="drive until the queue is empty, then exit")
    args = parser.parse_args(argv)
    return serve(args.poll_s, args.once)


if __name__ == "__main__":
    sys.exit(main())
