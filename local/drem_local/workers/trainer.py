"""The learning booth's worker: trains one job at a time, then races the new model version on the job's track.

`drem up` starts it beside the app server and restarts it if it dies (drem_local.supervise); `drem status` shows it.
It reads the same environment as the app (tables, buckets, the local storage endpoint) and works through the app's
own services, so a trained model goes through exactly the upload validation and scrutineering any racer's upload
gets. Per job (chalicelib.domain.booth_training):

1. download the job's runs from the runs bucket into a temporary dataset folder (the snapshot manifest records them);
2. behaviour cloning (`drem_sim.learn.pipeline.train_to_archive`: train, export ONNX, check it, package the archive),
   reporting progress, epoch and loss to the job as it goes;
3. submit the archive as the racer's next version (v0001, v0002 …) through `ModelService.submit_archive`;
4. scrutineer it (`ScrutineerService`, the default event track) and drive an autonomous run of it on the job's track,
   whose metrics are computed like any run's and recorded as the version's evaluation in the model registry.

Autonomous runs a racer asks for (`POST /api/runs` with mode autonomous) are driven between jobs.
Bounded CPU, so live pages keep their latency: the process runs at the lowest priority (nice +10, and SCHED_IDLE on
Linux, as the scrutineering worker: only on CPU time nothing else wants; nice alone left training a share of the
core), on the last core when the machine has more than one (with all background work, chalicelib.contained), and
torch, OpenCV and onnxruntime each use one thread. Training needs torch
(the `train` extra); when it is not installed the worker says so at start and fails each job with that reason
instead of a traceback.

    python -m drem_local.workers.trainer [--poll 1.0] [--once]
"""
from __future__ import annotations

import argparse
import importlib.util
import io
import os
import re
import shutil
import signal
import sys
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any, TextIO, cast

NICENESS = 10
POLL_S = 1.0
REPORT_EVERY_S = 0.5
SECONDS_PER_LAP_LIMIT = 40.0  # an autonomous run ends after this much simulated time per lap attempt
NO_TORCH = ("training needs PyTorch, which is not installed on this server: install the train extra "
            "(pip install -e '.[train]', or make install-test) and restart drem up")
# The job's progress bar: downloading 0 → TRAIN_FROM, training → EXPORT_AT, exporting → CHECK_AT, checking it like an
# upload, scrutineering and its autonomous run → 1.
TRAIN_FROM, EXPORT_AT, CHECK_AT = 0.05, 0.85, 0.9
_EXPORTING = "exporting the model"  # how drem_sim.learn.pipeline.EXPORTING begins (that module needs torch)
_BAR = re.compile(r"epoch (\d+)/(\d+) \[([#.]+)\] loss ([0-9.]+)")
_EPOCH = re.compile(r"epoch (\d+)/(\d+) train ([0-9.]+)")


def bound_cpu() -> list[int]:
    """The lowest priority (nice and SCHED_IDLE) on one core, the last of several, as all background work
    (chalicelib.contained); one thread per library. Returns the cores it may use."""
    from chalicelib.contained import lowest_priority

    cores = lowest_priority(NICENESS)
    for variable in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[variable] = "1"
    import cv2

    cv2.setNumThreads(1)
    return cores


def torch_installed() -> bool:
    return importlib.util.find_spec("torch") is not None and importlib.util.find_spec("onnx") is not None


class JobProgress(io.TextIOBase):
    """The training progress stream (`drem train`'s bar), turned into the job's progress, epoch and loss."""

    def __init__(self, training: Any, job: Any, clock: Any = time.monotonic) -> None:
        self.training, self.job, self._clock = training, job, clock
        self._reported_at = 0.0

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        bar, summary = _BAR.findall(text), _EPOCH.findall(text)
        if _EXPORTING in text:
            self.job = self.training.report(self.job, progress=EXPORT_AT, epoch=self.job.epoch, loss=self.job.loss,
                                            stage="exporting the model")
        elif summary:
            epoch, epochs, loss = summary[-1]
            self._report(int(epoch) / int(epochs), int(epoch), float(loss), force=True)
        elif bar:
            epoch, epochs, filled, loss = bar[-1]
            done = (int(epoch) - 1 + filled.count("#") / len(filled)) / int(epochs)
            self._report(done, int(epoch), float(loss))
        return len(text)

    def _report(self, fraction: float, epoch: int, loss: float, *, force: bool = False) -> None:
        if not force and self._clock() - self._reported_at < REPORT_EVERY_S:
            return
        self._reported_at = self._clock()
        self.job = self.training.report(self.job, progress=TRAIN_FROM + (EXPORT_AT - TRAIN_FROM) * fraction,
                                        epoch=epoch, loss=loss)


class Trainer:
    def __init__(self, say: Any = print) -> None:
        from chalicelib import services

        self.services = services
        self.say = say
        self.training = services.training_service()
        self.runs = self.training.runs
        self.can_train = torch_installed()
        self.booth_in_use = False  # a visitor has driven (a run exists): training may be asked for from now on
        self.warmed_up = False

    # -- the loop ----------------------------------------------------------------------------------------------------

    def work_once(self) -> bool:
        """Do one piece of work (a training job, else one autonomous run); False when there was nothing to do."""
        job = self.training.claim_next()
        if job is not None:
            self.booth_in_use = True
            self.train(job)
            self.warmed_up = self.can_train  # training loaded all a warm-up would
            return True
        runs = self.runs.store.all_runs()
        self.booth_in_use = self.booth_in_use or bool(runs)
        run = next((r for r in sorted(runs, key=lambda r: r.created_at) if r.status.value == "QUEUED"), None)
        if run is not None:
            self.drive(run)
            return True
        return False

    def warm_up_once_the_booth_is_in_use(self) -> None:
        """Load PyTorch (~800 modules and a first optimiser step: 5-7 s of CPU, ~300 MB) when a visitor starts their
        first drive, minutes before they can press Train, so no visitor waits for it; an event that never uses the
        booth never pays it (drem up starts this worker on every laptop)."""
        if self.warmed_up or not self.can_train or not self.booth_in_use:
            return
        self.say("trainer: a visitor is driving; loading PyTorch so their first training starts at once")
        import drem_sim.learn.pipeline  # noqa: F401
        from drem_sim.learn.train import warm_up

        warm_up()
        self.warmed_up = True

    # -- training ----------------------------------------------------------------------------------------------------

    def train(self, job: Any) -> None:
        started = time.monotonic()
        self.say(f"trainer: job {job.job_id} of {job.owner_username}: {len(job.run_ids)} runs, {job.epochs} epochs")
        if not self.can_train:
            self.training.fail(job, NO_TORCH)
            return
        folder = Path(tempfile.mkdtemp(prefix="drem-train-"))
        try:
            model, run_id = self._train_and_submit(job, folder)
        except Exception as error:  # noqa: BLE001 - the racer sees why their job failed, the log has the traceback
            if storage_away(error):  # not the job's fault: it is queued again once storage answers (main loop)
                self.say(f"trainer: job {job.job_id} was cut off by storage going away; it is taken again")
                raise
            self.say(f"trainer: job {job.job_id} failed: {traceback.format_exc()}")
            latest = self.training.store.get_job(job.job_id) or job
            self.training.fail(latest, _reason(error))
            return
        finally:
            shutil.rmtree(folder, ignore_errors=True)
        self.say(f"trainer: job {job.job_id} done in {time.monotonic() - started:.1f}s: {model.name} "
                 f"({model.status.value}), autonomous run {run_id}")

    def _train_and_submit(self, job: Any, folder: Path) -> tuple[Any, str | None]:
        from chalicelib.settings import get_settings
        from chalicelib.storage import clients
        from drem_sim.learn.pipeline import train_to_archive
        from drem_sim.learn.train import TrainConfig
        from drem_sim.runs import download_run

        models = self.services.model_service()
        submitted = models.store.get(job.owner_sub, job.model_id) if job.model_id else None
        if submitted is not None and submitted.status.value == "AVAILABLE":
            # Taken again after a restart that came after the submit: that version is this job's (never a second).
            self.say(f"trainer: job {job.job_id} had already submitted {submitted.name}; finishing it")
            return self._race_version(job, submitted)
        bucket = get_settings().bucket("runs")
        run_dirs = []
        for number, run_id in enumerate(job.run_ids):
            job = self.training.report(job, progress=TRAIN_FROM * number / len(job.run_ids), epoch=0, loss=None,
                                       stage=f"downloading your drives ({number + 1} of {len(job.run_ids)})")
            record = self.runs.store.get_run(run_id)
            if record is None:
                raise RuntimeError(f"run {run_id} no longer exists")
            run_dirs.append(download_run(f"s3://{bucket}/{record.prefix}", folder / "runs", clients.s3()))
        name = job.model_name or self.training.next_version_name(job.owner_sub)
        if not job.model_id:  # the version's key, on the job before anything is submitted under it
            from chalicelib.domain.racer_models import new_model_id

            job = self.training.plan_version(job, new_model_id(), name)
        job = self.training.report(job, progress=TRAIN_FROM, epoch=0, loss=None,
                                   stage=f"reading the {job.frames} frames of your drives")
        progress = JobProgress(self.training, job)
        config = TrainConfig(epochs=job.epochs, seed=0, batch_size=32, num_threads=1)
        trained = train_to_archive(run_dirs, folder / "model", name, config, progress=cast(TextIO, progress),
                                   extra_lineage={"booth_job": job.job_id})
        job = self.training.report(progress.job, progress=CHECK_AT, epoch=progress.job.epoch, loss=progress.job.loss,
                                   stage="checking the model like an upload")
        model = models.submit_archive(job.owner_sub, job.owner_username, name, trained.archive.read_bytes(),
                                      model_id=job.model_id)
        if model.status.value != "AVAILABLE":
            raise RuntimeError(f"the trained model was not accepted: {model.reason}")
        return self._race_version(job, model)

    def _race_version(self, job: Any, model: Any) -> tuple[Any, str | None]:
        """Scrutineer the job's version and drive its autonomous run (the one recorded on the job, if a restart
        came after it was made), then finish the job."""
        from chalicelib.core.principals import User
        from chalicelib.domain.booth_runs import NewRun, RunMode, RunStatus
        from chalicelib.domain.model_scrutiny import ScrutineerRequest

        name = model.name
        racer = User(sub=job.owner_sub, username=job.owner_username, groups=frozenset({"racer"}))
        job = self.training.report(job, progress=0.93, epoch=job.epoch, loss=job.loss,
                                   stage=f"scrutineering {name}")
        try:
            self.services.scrutineer_service().scrutineer(racer, model.model_id, ScrutineerRequest(laps=1))
        except Exception as error:  # noqa: BLE001 - the version stays usable; scrutineering can be asked for again
            self.say(f"trainer: scrutineering {name} failed: {_reason(error)}")
        run = self.runs.store.get_run(job.autonomous_run_id) if job.autonomous_run_id else None
        if run is None:  # made, but cut off before the job recorded it: the run carries the job's id
            run = next((r for r in self.runs.store.all_runs() if r.job_id == job.job_id), None)
            if run is not None:
                job = self.training.plan_autonomous_run(job, run.run_id)
        if run is None:
            run = self.runs.create(racer, NewRun(track_id=job.track_id, mode=RunMode.AUTONOMOUS,
                                                 model_id=model.model_id), job_id=job.job_id)
            job = self.training.plan_autonomous_run(job, run.run_id)
        elif run.status is RunStatus.RUNNING:  # the worker that drove it died: drive it again from the start
            run = self.runs.mark(run, RunStatus.QUEUED)
        job = self.training.report(job, progress=0.96, epoch=job.epoch, loss=job.loss,
                                   stage=f"{name} drives {job.track_id} on its own")
        if run.status is RunStatus.QUEUED:
            self.drive(run)
        self.training.finish(job, model, autonomous_run_id=run.run_id)
        return model, run.run_id

    # -- autonomous runs ---------------------------------------------------------------------------------------------

    def drive(self, run: Any) -> None:
        from chalicelib.domain.booth_runs import RunStatus

        try:
            running = self.runs.mark(run, RunStatus.RUNNING)
        except Exception:  # noqa: BLE001 - another worker took it
            return
        folder = Path(tempfile.mkdtemp(prefix="drem-drive-"))
        try:
            finished = self._drive(running, folder)
            self._record_evaluation(finished)
        except Exception as error:  # noqa: BLE001 - the racer sees why; the log has the traceback
            if run.job_id and storage_away(error):  # its job is taken again, which drives it again from the start
                raise
            self.say(f"trainer: autonomous run {run.run_id} failed: {traceback.format_exc()}")
            latest = self.runs.store.get_run(run.run_id) or running
            if latest.status is RunStatus.RUNNING:
                self.runs.mark(latest, RunStatus.FAILED, _reason(error))
        finally:
            shutil.rmtree(folder, ignore_errors=True)

    def _drive(self, run: Any, folder: Path) -> Any:
        from drem_sim.env import RaceEnv
        from drem_sim.learn.pilot import OnnxPilot
        from drem_sim.runs import record_run
        from drem_sim.tracks import load_track

        models = self.runs.models
        model = models.store.get_by_id(run.model_id or "")
        download = models.files.download_bounded(model.s3_key or "", limit=models.max_upload_bytes) if model else None
        if download is None or download.too_large:
            raise RuntimeError("the model's archive is missing")
        archive = folder / "model.tar.gz"
        with download.body:
            archive.write_bytes(download.body.read())
        pilot = OnnxPilot.from_archive(archive)
        env = RaceEnv(load_track(run.track_id))
        limit = int(run.laps_requested * SECONDS_PER_LAP_LIMIT * env.config.decision_hz)
        run_dir = record_run(env, lambda observation, _params: pilot.act(observation), folder / "runs",
                             laps=run.laps_requested, driver=f"model:{run.model_name}", max_steps=limit,
                             run_id=run.run_id)
        from drem_sim.runs import run_objects

        for name, data in run_objects(run_dir).items():  # three objects: controls, the frames bundle, the first frame
            self.runs.files.put(run.prefix + name, data)
        return self.runs.finalise_record(run)

    def _record_evaluation(self, run: Any) -> None:
        """The run's metrics as the version's evaluation: the registry's timeline and per-track plots show it."""
        from chalicelib.core.principals import User
        from chalicelib.domain.model_registry import EvaluationInput

        metrics = run.metrics
        if metrics is None or not run.model_id or metrics.attempts < 1:
            return
        racer = User(sub=run.owner_sub, username=run.owner_username, groups=frozenset({"racer"}))
        self.services.registry_service().record(racer, run.model_id, EvaluationInput(
            track=run.track_id, attempts=metrics.attempts, laps_completed=metrics.laps_completed,
            completion_pct=metrics.completion_pct, offtrack_count=metrics.offtrack_count,
            lap_times_s=metrics.lap_times_s, steering_jitter_deg=metrics.stability_deg, source="booth"))


def storage_away(error: BaseException) -> bool:
    """Storage stopped answering (restarting after a crash): the work is taken again when it is back. A full disk is
    not that: it is said to the racer as the job's reason."""
    from chalicelib.core.errors import ServiceUnavailable, StorageDiskFull

    return isinstance(error, ServiceUnavailable) and not isinstance(error, StorageDiskFull)


def _reason(error: Exception) -> str:
    message = getattr(error, "message", None) or str(error) or type(error).__name__
    return f"{type(error).__name__}: {message}"[:400]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drem_local.workers.trainer", description=__doc__.splitlines()[0])
    parser.add_argument("--poll", type=float, default=POLL_S, help="seconds between looks at an empty queue")
    parser.add_argument("--once", action="store_true", help="do what is queued now, then exit")
    args = parser.parse_args(argv)
    from drem_local.app_source import use_app_source

    use_app_source()
    cores = bound_cpu()
    say = lambda line: print(line, flush=True)  # noqa: E731 - one line to stdout (the supervisor's log)
    stopping = False

    def stop(_signum: int, _frame: object) -> None:
        nonlocal stopping
        stopping = True

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    trainer = Trainer(say)
    idle_class = getattr(os, "SCHED_IDLE", None) is not None and os.sched_getscheduler(0) == os.SCHED_IDLE
    say(f"trainer: ready (nice +{NICENESS}{', SCHED_IDLE' if idle_class else ''}, cores {cores or 'all'}, one thread); "
        + ("training with PyTorch" if trainer.can_train else f"NOT training: {NO_TORCH}"))
    # Jobs a dead trainer left RUNNING (or this one, when storage went away under it) go back to the queue once
    # storage answers. drem up runs one trainer per stack, so a RUNNING job this idle one holds is nobody's.
    requeued = False
    while not stopping:
        try:
            if not requeued:
                for job in trainer.training.requeue_interrupted():
                    say(f"trainer: job {job.job_id} was interrupted by a restart; queued again")
                requeued = True
            busy = trainer.work_once()
        except Exception:  # noqa: BLE001 - storage briefly away (a restart): say so and look again
            say(f"trainer: could not reach the queue: {traceback.format_exc(limit=2)}")
            busy = False
            requeued = False  # the job it had (if any) is RUNNING with nobody training it: queued again
        if args.once and not busy:
            return 0
        trainer.warm_up_once_the_booth_is_in_use()
        if not busy:
            deadline = time.monotonic() + args.poll
            while not stopping and time.monotonic() < deadline:
                time.sleep(0.1)
    say("trainer: stopped")
    return 0


if __name__ == "__main__":
    sys.exit(main())
