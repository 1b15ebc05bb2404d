"""The booth worker, in process on the test stack: a queued job becomes the racer's next version (validated and
scrutineered like an upload), which then drives an autonomous run whose metrics reach the registry; without torch
the job fails with a reason a person can act on."""
from __future__ import annotations

from typing import Any

import pytest

from drem_local.workers.trainer import NO_TORCH, JobProgress, Trainer
from drem_sim.learn.pipeline import EXPORTING
from tests.unit.models_helpers import ModelsApi

pytestmark = pytest.mark.unit


def drive_and_queue(api: ModelsApi, steps: int = 60, epochs: int = 1) -> tuple[str, str]:
    started = api.call("POST", "/api/drive", {"track_id": "drem_oval"}).json_body
    for index in range(steps):
        api.call("POST", f"/api/runs/{started['run_id']}/drive",
                 {"throttle": 0.5, "steering": 0.3 if index % 20 < 10 else -0.3})
    assert api.call("POST", f"/api/runs/{started['run_id']}/drive/finish").status_code == 200
    job = api.call("POST", "/api/training-jobs", {"run_ids": [started["run_id"]], "epochs": epochs})
    assert job.status_code == 201, job.json_body
    return started["run_id"], job.json_body["job"]["job_id"]


def test_a_job_becomes_v0001_scrutineered_raced_and_evaluated(alice: ModelsApi, client: Any) -> None:
    _, job_id = drive_and_queue(alice)
    said: list[str] = []
    trainer = Trainer(said.append)
    assert trainer.work_once() is True
    job = alice.call("GET", f"/api/training-jobs/{job_id}").json_body["job"]
    assert job["status"] == "DONE", (job, said)
    assert job["progress"] == 1.0 and job["stage"] == ""
    assert job["model_name"] == "v0001" and job["loss"] is not None and job["epoch"] == 1
    model = alice.call("GET", f"/api/models/{job['model_id']}").json_body["model"]
    assert model["status"] == "AVAILABLE" and model["training_algorithm"] in ("behaviour_cloning", "clipped_ppo")
    assert model["scrutineer_result"] is not None
    run = alice.call("GET", f"/api/runs/{job['autonomous_run_id']}").json_body["run"]
    assert (run["mode"], run["status"], run["model_name"]) == ("autonomous", "FINALISED", "v0001")
    assert run["metrics"]["frames"] > 0 and run["metrics"]["attempts"] >= 1
    evaluations = alice.call("GET", f"/api/models/{job['model_id']}/evaluations").json_body["evaluations"]
    assert [(e["track"], e["source"]) for e in evaluations] == [("drem_oval", "booth")]
    assert evaluations[0]["completion_pct"] == run["metrics"]["completion_pct"]
    assert trainer.work_once() is False  # nothing else queued


def test_without_torch_the_job_fails_saying_what_to_install(alice: ModelsApi) -> None:
    _, job_id = drive_and_queue(alice, steps=5)
    trainer = Trainer(lambda line: None)
    trainer.can_train = False
    trainer.work_once()
    job = alice.call("GET", f"/api/training-jobs/{job_id}").json_body["job"]
    assert job["status"] == "FAILED" and job["reason"] == NO_TORCH and "train extra" in NO_TORCH


def test_pytorch_loads_when_a_visitor_starts_driving_not_on_every_laptop(alice: ModelsApi, monkeypatch: Any) -> None:
    # drem up starts the trainer on every laptop: loading PyTorch there cost 7.5 s of CPU at every start, booth or not.
    import drem_sim.learn.train

    warm_ups: list[int] = []
    monkeypatch.setattr(drem_sim.learn.train, "warm_up", lambda: warm_ups.append(1))
    said: list[str] = []
    trainer = Trainer(said.append)
    for _ in range(3):  # the worker's loop: idle polls of an event nobody drives at
        assert trainer.work_once() is False
        trainer.warm_up_once_the_booth_is_in_use()
    assert warm_ups == [] and not any("PyTorch" in line for line in said)

    alice.call("POST", "/api/drive", {"track_id": "drem_oval"})  # a visitor starts their first drive
    for _ in range(3):
        trainer.work_once()
        trainer.warm_up_once_the_booth_is_in_use()
    assert warm_ups == [1]
    assert any("a visitor is driving; loading PyTorch" in line for line in said)


class Job:
    def __init__(self, epoch: int, loss: float | None) -> None:
        self.epoch, self.loss = epoch, loss


class Reports:
    def __init__(self) -> None:
        self.seen: list[tuple[float, int, float | None]] = []

    def report(self, job: Any, *, progress: float, epoch: int, loss: float | None, stage: str = "training") -> Any:
        self.seen.append((round(progress, 3), epoch, loss) + (() if stage == "training" else (stage,)))
        return Job(epoch, loss)


def test_the_progress_bar_becomes_progress_epoch_and_loss() -> None:
    reports, now = Reports(), [0.0]
    stream = JobProgress(reports, job=Job(0, None), clock=lambda: now[0])
    now[0] = 1.0
    stream.write("\repoch 1/2 [##########..........] loss 0.5000    3.0s")
    stream.write("\repoch 1/2 [###########.........] loss 0.4900    3.1s")  # too soon after the last: not sent
    stream.write("\repoch 1/2 train 0.4500 val 0.5100    6.0s\n")  # an epoch's end is always sent
    stream.write(f"{EXPORTING}\n")  # after the last epoch: the page says so instead of sitting on "epoch 2/2"
    assert reports.seen == [(0.25, 1, 0.5), (0.45, 1, 0.45), (0.85, 1, 0.45, "exporting the model")]


class _PowerCut(BaseException):
    """kill -9 of the trainer: nothing after this point of it runs, not even its own error handling."""


@pytest.mark.parametrize("kill_point", ["after the version was submitted", "while the autonomous run drives"])
def test_a_trainer_killed_midway_finishes_the_same_version_and_run_when_it_takes_the_job_again(
        alice: ModelsApi, monkeypatch: pytest.MonkeyPatch, kill_point: str) -> None:
    from chalicelib.domain.racer_models import ModelService

    _, job_id = drive_and_queue(alice)
    if kill_point == "after the version was submitted":
        real_submit = ModelService.submit_archive

        def submit_then_die(self, *args, **kwargs):  # type: ignore[no-untyped-def]
            real_submit(self, *args, **kwargs)
            raise _PowerCut()
        monkeypatch.setattr(ModelService, "submit_archive", submit_then_die)
    else:
        monkeypatch.setattr(Trainer, "_drive", lambda self, run, folder: (_ for _ in ()).throw(_PowerCut()))
    with pytest.raises(_PowerCut):
        Trainer(lambda line: None).work_once()
    monkeypatch.undo()

    restarted = Trainer(lambda line: None)  # what drem up's supervisor starts after the crash
    assert [job.job_id for job in restarted.training.requeue_interrupted()] == [job_id]
    assert restarted.work_once() is True

    job = alice.call("GET", f"/api/training-jobs/{job_id}").json_body["job"]
    assert job["status"] == "DONE" and job["model_name"] == "v0001", job
    models = alice.call("GET", "/api/models").json_body["models"]
    assert [(m["name"], m["status"]) for m in models] == [("v0001", "AVAILABLE")]  # no copy refused as a duplicate
    assert models[0]["model_id"] == job["model_id"]
    runs = [r for r in alice.call("GET", "/api/runs").json_body["runs"] if r.get("job_id") == job_id]
    assert [(r["run_id"], r["status"]) for r in runs] == [(job["autonomous_run_id"], "FINALISED")]


def test_a_claim_stored_before_storage_went_away_is_still_the_workers_job(alice: ModelsApi,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """The claim's write reached storage but its answer was lost; the retry then found the job RUNNING. Skipping it
    would leave the visitor's job RUNNING with nobody training it."""
    from chalicelib.domain.booth_runs import RecordChanged

    _, job_id = drive_and_queue(alice, steps=5)
    training = Trainer(lambda line: None).training
    real_replace = type(training.store).replace_job

    def stored_then_lost(self, job, *, expected_status):  # type: ignore[no-untyped-def]
        real_replace(self, job, expected_status=expected_status)
        raise RecordChanged("the retry of a write that was stored")
    monkeypatch.setattr(type(training.store), "replace_job", stored_then_lost)
    claimed = training.claim_next()
    monkeypatch.undo()
    assert claimed is not None and claimed.job_id == job_id
    assert alice.call("GET", f"/api/training-jobs/{job_id}").json_body["job"]["status"] == "RUNNING"


def test_a_job_cut_off_by_storage_going_away_is_taken_again_not_failed(alice: ModelsApi,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    from chalicelib.core.errors import ServiceUnavailable

    _, job_id = drive_and_queue(alice)
    trainer = Trainer(lambda line: None)

    def storage_gone(self, job, folder):  # type: ignore[no-untyped-def]
        raise ServiceUnavailable("The booth store cannot be reached.")
    monkeypatch.setattr(Trainer, "_train_and_submit", storage_gone)
    with pytest.raises(ServiceUnavailable):  # to the worker's loop, which queues it again once storage answers
        trainer.work_once()
    monkeypatch.undo()
    assert alice.call("GET", f"/api/training-jobs/{job_id}").json_body["job"]["status"] == "RUNNING"  # not FAILED

    assert [job.job_id for job in trainer.training.requeue_interrupted()] == [job_id]
    assert trainer.work_once() is True
    job = alice.call("GET", f"/api/training-jobs/{job_id}").json_body["job"]
    assert job["status"] == "DONE" and job["model_name"] == "v0001", job


def test_the_trainer_takes_only_the_cpu_the_live_pages_do_not_want() -> None:
    """Training fills a core for as long as it runs; on a 2-core venue laptop a spectator's poll or a lap crossing
    must take that core from it at once (SCHED_IDLE, niced, as the scrutineering worker), not wait for its share."""
    import os
    import subprocess
    import sys

    from tests.user_processes import from_a_shell

    probe = ("import os; from drem_local.app_source import use_app_source; use_app_source(); "
             "from drem_local.workers.trainer import bound_cpu; cores = bound_cpu(); "
             "print(os.sched_getscheduler(0), os.getpriority(os.PRIO_PROCESS, 0), len(os.sched_getaffinity(0)))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120,
                          preexec_fn=from_a_shell)  # noqa: PLW1509 - a normal-priority start, as drem up's
    assert done.returncode == 0, done.stderr
    policy, nice, cores = (int(word) for word in done.stdout.split())
    assert policy == os.SCHED_IDLE
    assert nice >= 10
    assert cores == 1  # the last of several, with all background work: the other cores stay free for the pages
