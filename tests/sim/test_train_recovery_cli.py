"""`drem train --drift` (recovery laps) and `--balance-steering`/`--balance-cap`, through the installed `drem`."""
from __future__ import annotations

import json
import subprocess
import tarfile
from pathlib import Path

import numpy as np
import pytest

from drem_sim.learn.train import steering_balance

pytestmark = pytest.mark.sim

REPO = Path(__file__).resolve().parents[2]
DREM = REPO / ".venv" / "bin" / "drem"


def _drem(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(DREM), *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def _lineage(archive: Path) -> dict:
    with tarfile.open(archive) as tar:
        member = next(m for m in tar.getmembers() if m.name.endswith("lineage.json"))
        handle = tar.extractfile(member)
        assert handle is not None
        return json.loads(handle.read())


def test_drift_records_recovery_laps_labelled_with_the_demonstrators_correction(tmp_path: Path) -> None:
    done = _drem("train", "--tracks", "drem_chicane", "--demo-laps", "1", "--drift", "12", "--drift-laps", "1",
                 "--balance-steering", "--balance-cap", "4", "--epochs", "1", "--out", str(tmp_path / "m"),
                 "--name", "recovery", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "round 0: recovery laps, 1 lap(s) with 12 degree pushes on each of 1 track direction(s)" in done.stderr

    recovery = sorted((tmp_path / "m" / "runs" / "round-0-recovery").rglob("controls.jsonl"))
    assert len(recovery) == 1  # one recovery run per track direction
    meta = json.loads((recovery[0].parent / "metadata.json").read_text())
    assert meta["driver"] == "recovery" and meta["recovery"] == {"drift_deg": 12.0}
    rows = [json.loads(line) for line in recovery[0].read_text().splitlines()]
    pushed = [r for r in rows if abs(r["executed_steering_angle"] - r["steering_angle"]) > 1.0]
    # The car was really pushed aside for a good share of the lap, and what it learns is the unpushed action.
    assert len(pushed) > len(rows) // 10
    assert all(abs(r["executed_steering_angle"] - r["steering_angle"]) <= 12.0 + 1e-3 for r in rows)
    # In the chicane's tight bends the pushes send the car wide (against the demonstrator's steering).
    in_bends = [r for r in pushed if abs(r["steering_angle"]) >= 15.0]
    outwards = [r for r in in_bends if (r["executed_steering_angle"] - r["steering_angle"]) * r["steering_angle"] < 0]
    assert in_bends and len(outwards) >= 0.8 * len(in_bends)

    lineage = _lineage(tmp_path / "m" / "recovery.tar.gz")
    assert lineage["dagger"]["recovery"] == {"drift_deg": 12.0, "laps_per_track": 1}
    assert lineage["balance_steering"] == {"cap": 4.0}
    assert lineage["dataset"]["frame_count"] > len(rows)  # the demonstrator's lap and the recovery lap


def test_balance_steering_trains_recorded_runs_and_says_so_in_the_lineage(tmp_path: Path) -> None:
    assert _drem("sim", "record", "--track", "drem_chicane", "--laps", "1", "--out", str(tmp_path / "runs"),
                 cwd=tmp_path).returncode == 0
    done = _drem("train", "--runs", str(tmp_path / "runs"), "--balance-steering", "--epochs", "1", "--out",
                 str(tmp_path / "m"), "--name", "balanced", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert _lineage(tmp_path / "m" / "balanced.tar.gz")["balance_steering"] == {"cap": 8.0}  # the default cap
    plain = _drem("train", "--runs", str(tmp_path / "runs"), "--epochs", "1", "--out", str(tmp_path / "p"),
                  "--name", "plain", cwd=tmp_path)
    assert plain.returncode == 0 and _lineage(tmp_path / "p" / "plain.tar.gz")["balance_steering"] is None


def test_drift_and_balance_cap_mistakes_are_refused_before_any_work(tmp_path: Path) -> None:
    (tmp_path / "runs").mkdir()
    done = _drem("train", "--runs", str(tmp_path / "runs"), "--drift", "10", "--out", str(tmp_path / "m"),
                 cwd=tmp_path)
    assert done.returncode == 2 and "--drift records recovery laps on --tracks" in done.stderr
    done = _drem("train", "--tracks", "drem_oval", "--drift", "45", "--out", str(tmp_path / "m"), cwd=tmp_path)
    assert done.returncode == 2 and "--drift is 0..30 degrees" in done.stderr
    done = _drem("train", "--tracks", "drem_oval", "--balance-steering", "--balance-cap", "0.5", "--out",
                 str(tmp_path / "m"), cwd=tmp_path)
    assert done.returncode == 2 and "--balance-cap is at least 1" in done.stderr
    assert not (tmp_path / "m").exists()


def test_balance_draws_sharp_steer_frames_more_often_up_to_the_cap() -> None:
    # 90 straight frames, 30 in a bend, 1 at full lock: a plain epoch shows full lock once in 121 frames.
    steering = np.array([0.5] * 90 + [-10.0] * 30 + [29.0], dtype=np.float32)
    chances = steering_balance(steering, cap=8.0)
    assert chances.sum() == pytest.approx(1.0)
    straight, bend, lock = chances[0], chances[90], chances[120]
    assert bend / straight == pytest.approx(3.0)  # 3x rarer, drawn 3x as often: the bins weigh the same
    assert lock / straight == pytest.approx(8.0)  # 90x rarer, drawn only 8x as often: not learned by heart
    # A left and a right bend of the same sharpness share a bin (mirroring already makes the sign moot).
    mirrored = steering_balance(np.array([10.0, -10.0, 0.0, 0.0, 0.0, 0.0]), 8.0)
    assert mirrored[0] == mirrored[1] == pytest.approx(2 * mirrored[2])
    with pytest.raises(ValueError, match="at least 1"):
        steering_balance(steering, cap=0.5)
