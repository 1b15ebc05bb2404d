"""DAgger rounds, multi-track training and camera-matched augmentation: data that teaches recovery."""
from __future__ import annotations

import io
import json
import os
import subprocess
import tarfile
from pathlib import Path

import numpy as np
import pytest

from drem_sim.demonstrator import Demonstrator
from drem_sim.learn.dataset import Augmentation, DatasetError, augment_batch
from drem_sim.learn.track_sets import TrackDirection
from drem_sim.tracks import load_track

pytestmark = pytest.mark.sim

REPO = Path(__file__).resolve().parents[2]
DREM = REPO / ".venv" / "bin" / "drem"


@pytest.fixture(scope="module")
def dagger_run(tmp_path_factory: pytest.TempPathFactory):
    from drem_sim.learn.dagger import DaggerConfig, run_dagger
    from drem_sim.learn.train import TrainConfig

    out = tmp_path_factory.mktemp("dagger")
    config = DaggerConfig(train_tracks=[TrackDirection("drem_oval"), TrackDirection("drem_oval", True)],
                          eval_tracks=[TrackDirection("reinvent_base")], rounds=1, demo_laps=1, first_epochs=1,
                          round_epochs=1, eval_laps=1, seed=3)
    train = TrainConfig(batch_size=64, num_threads=1, augmentation=Augmentation.from_names(["brightness", "shift",
                                                                                            "blur"]))
    progress = io.StringIO()
    reports = run_dagger(config, out, "dagger-test", train, progress=progress)
    return out, reports, progress.getvalue()


def test_each_round_adds_model_driven_runs_labelled_by_the_demonstrator(dagger_run) -> None:
    out, reports, _progress = dagger_run
    assert [r.round for r in reports] == [0, 1]
    assert reports[1].frames > reports[0].frames and reports[1].runs == reports[0].runs + 2
    dagger_runs = sorted((out / "runs" / "round-1").rglob("controls.jsonl"))
    assert len(dagger_runs) == 2  # one per training track and direction
    rows = [json.loads(line) for line in dagger_runs[0].read_text().splitlines()]
    meta = json.loads((dagger_runs[0].parent / "metadata.json").read_text())
    assert meta["driver"] == "dagger-round-1" and meta["dagger"]["round"] == 1
    # The label is what the demonstrator does from the pose the model drove to (it differs from what was executed).
    track = load_track("drem_oval", reverse=meta["direction"] == "reverse")
    teacher = Demonstrator(track)
    row = rows[20]
    expected = teacher.act({"x": row["x"], "y": row["y"], "heading": row["heading"],
                            "projection_distance": float(track.project((row["x"], row["y"])).s[0])})
    assert row["steering_angle"] == pytest.approx(expected["steering_angle"], abs=0.5)
    assert any(abs(r["steering_angle"] - r["executed_steering_angle"]) > 0.5 for r in rows)


def test_rounds_are_recorded_in_the_archive_lineage_and_plotted(dagger_run) -> None:
    out, reports, _progress = dagger_run
    with tarfile.open(out / "dagger-test.tar.gz") as archive:
        lineage = json.load(archive.extractfile("training/lineage.json"))
    assert lineage["dagger"]["round"] == 1
    assert lineage["dagger"]["train_tracks"] == ["drem_oval", "drem_oval:reverse"]
    assert lineage["dagger"]["held_out_tracks"] == ["reinvent_base"]
    assert lineage["dagger"]["previous_rounds"][0]["evaluation"][0]["track"] == "reinvent_base"
    assert lineage["augmentation"]["names"] == ["brightness", "shift", "blur"]
    rounds = json.loads((out / "rounds.json").read_text())
    assert [r["evaluation"][0]["track"] for r in rounds] == ["reinvent_base", "reinvent_base"]
    import cv2

    plot = cv2.imread(str(out / "rounds.png"))
    assert plot is not None and plot.shape == (360, 640, 3) and (plot < 250).any()


def test_shift_and_blur_change_the_image_not_the_label() -> None:
    rng = np.random.default_rng(0)
    images = np.zeros((8, 120, 160), np.uint8)
    images[:, :, 78:82] = 255  # a sharp white line
    targets = np.tile(np.array([[0.3, -0.2]], np.float32), (8, 1))
    shifted, labels = augment_batch(images, targets, rng, augmentation=Augmentation(brightness=0, noise=0, flip=False,
                                                                                    shift_px=4.0, rotate_deg=2.0))
    assert np.array_equal(labels, targets)
    assert not np.array_equal(shifted.astype(np.uint8), images)
    assert abs(float(shifted.mean()) - float(images.mean())) < 2.0  # edges repeat: no black borders
    blurred, _ = augment_batch(images, targets, rng, augmentation=Augmentation(brightness=0, noise=0, flip=False,
                                                                               blur_probability=1.0))
    assert blurred.max() < 255 and (blurred[:, :, 76] > 0).all()  # the sharp edge spreads
    flipped, labels = augment_batch(images, targets, np.random.default_rng(1),
                                    augmentation=Augmentation(brightness=0, noise=0, flip=True))
    mirrored = np.flatnonzero(labels[:, 0] < 0)
    assert len(mirrored) and np.allclose(labels[mirrored, 0], -0.3)
    with pytest.raises(DatasetError, match="unknown augmentation"):
        Augmentation.from_names(["brightness", "fog"])


def test_train_without_the_train_extra_says_what_to_install(tmp_path: Path) -> None:
    blocker = tmp_path / "no_torch"
    (blocker / "torch").mkdir(parents=True)
    (blocker / "torch" / "__init__.py").write_text("raise ImportError('No module named torch (simulated)')\n")
    env = {**os.environ, "PYTHONPATH": str(blocker)}
    done = subprocess.run([str(DREM), "train", "--runs", str(tmp_path), "--out", str(tmp_path / "m")],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 2 and "train` extra" in done.stderr and "make install-test" in done.stderr


def test_train_refuses_a_hold_out_that_leaves_nothing_and_unknown_tracks(tmp_path: Path) -> None:
    done = subprocess.run([str(DREM), "train", "--tracks", "drem_oval", "--hold-out", "drem_oval", "--out",
                           str(tmp_path / "m")], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "leaves no track to train on" in done.stderr
    done = subprocess.run([str(DREM), "train", "--tracks", "drem_ovale", "--out", str(tmp_path / "m")],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "unknown track 'drem_ovale'" in done.stderr
    assert not (tmp_path / "m").exists()


def test_progress_shows_recording_driving_and_training(dagger_run) -> None:
    _out, _reports, progress = dagger_run
    assert "round 0 recording [####################] 2/2" in progress
    assert "round 1 driving [##########..........] 1/2 drem_oval:reverse" in progress
    assert "round 1 driving [####################] 2/2" in progress
    assert "epoch 1/1 train" in progress and "held out: reinvent_base" in progress
