"""A booth drive travels as a few objects, and the visitor's training job says what it is doing: the trainer fetches
a drive in a handful of requests however many frames it has (it used to fetch them one object at a time while the
page sat on "epoch 0/8"), and a drive saved after a kill -9 stays trainable even when the kill cut a frame."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.unit.booth_helpers import drive_lost_by_a_kill
from tests.unit.models_helpers import ModelsApi

pytestmark = pytest.mark.unit

FRAMES = 60
FEW_REQUESTS = 5  # list the prefix, the frames bundle, the controls, the metadata (and room for one more)


class CountingS3:
    """The trainer's S3 client, counting the requests a download makes."""

    def __init__(self, real: Any) -> None:
        self.real, self.requests = real, 0

    def get_object(self, **kwargs: Any) -> Any:
        self.requests += 1
        return self.real.get_object(**kwargs)

    def download_file(self, *args: Any, **kwargs: Any) -> Any:
        self.requests += 1
        return self.real.download_file(*args, **kwargs)

    def get_paginator(self, name: str) -> Any:
        counter, paginator = self, self.real.get_paginator(name)

        class Pages:
            def paginate(self, **kwargs: Any) -> Any:
                for page in paginator.paginate(**kwargs):
                    counter.requests += 1
                    yield page
        return Pages()


def test_train_fetches_the_drive_in_a_few_requests_and_the_job_says_each_step(
        alice: ModelsApi, monkeypatch: pytest.MonkeyPatch) -> None:
    from drem_local.workers.trainer import Trainer
    from drem_sim import runs

    started = alice.call("POST", "/api/drive", {"track_id": "drem_oval"}).json_body
    for index in range(FRAMES):
        alice.call("POST", f"/api/runs/{started['run_id']}/drive",
                   {"throttle": 0.5, "steering": 0.3 if index % 20 < 10 else -0.3})
    assert alice.call("POST", f"/api/runs/{started['run_id']}/drive/finish").status_code == 200
    job = alice.call("POST", "/api/training-jobs", {"run_ids": [started["run_id"]], "epochs": 2}).json_body["job"]

    clients: list[CountingS3] = []
    real_download = runs.download_run

    def counted_download(uri: str, target: Path, s3_client: Any = None) -> Path:
        clients.append(CountingS3(s3_client))
        return real_download(uri, target, clients[-1])
    monkeypatch.setattr(runs, "download_run", counted_download)
    trainer = Trainer(lambda line: None)
    shown: list[tuple[str, float]] = []  # what the jobs list shows, in order (the page renders the job's stage)
    real_report = trainer.training.report

    def seen(job: Any, **kwargs: Any) -> Any:
        stored = real_report(job, **kwargs)
        stage = f"training: epoch {stored.epoch}/{stored.epochs}" if stored.stage == "training" else stored.stage
        if not shown or shown[-1][0] != stage:
            shown.append((stage, stored.progress))
        return stored
    monkeypatch.setattr(trainer.training, "report", seen)
    assert trainer.work_once() is True

    done = alice.call("GET", f"/api/training-jobs/{job['job_id']}").json_body["job"]
    assert done["status"] == "DONE" and done["model_name"] == "v0001", done
    assert len(clients) == 1 and clients[0].requests <= FEW_REQUESTS < FRAMES
    assert [stage for stage, _ in shown] == [
        "downloading your drives (1 of 1)", f"reading the {FRAMES} frames of your drives",
        "training: epoch 1/2", "training: epoch 2/2", "exporting the model", "checking the model like an upload",
        "scrutineering v0001", "v0001 drives drem_oval on its own"]
    bar = [progress for _, progress in shown]
    assert bar == sorted(bar) and bar[0] < bar[-1] < 1.0  # the bar only moves forward; DONE fills it


def test_a_drive_saved_after_a_kill_that_cut_a_frame_is_still_trainable(alice: ModelsApi, tmp_path: Path) -> None:
    """The app writes a decision's frame, then its row: a kill -9 between them leaves a cut (here empty) frame that no
    row names. The saved drive holds every answered decision, and the trainer reads it."""
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from drem_sim.learn.dataset import load_snapshot
    from drem_sim.runs import download_run

    service, racer, run_id, run_folder = drive_lost_by_a_kill(tmp_path / "drives")
    (run_folder / "frames" / "000007.png").write_bytes(b"")  # the frame the kill cut; its row was never written

    saved = service.finish(racer, run_id)
    assert saved.status.value == "FINALISED" and saved.metrics is not None and saved.metrics.frames == 7

    folder = download_run(f"s3://{get_settings().bucket('runs')}/{saved.prefix}", tmp_path / "trainer", clients.s3())
    assert sorted(path.name for path in (folder / "frames").iterdir()) == [f"{i:06d}.png" for i in range(7)]
    assert load_snapshot([folder]).manifest["runs"][0]["rows"] == 7
