"""Evaluation that cannot flatter: a lap with a reset is no completed lap; one report row per track and direction."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from drem_sim.demonstrator import Demonstrator
from drem_sim.env import EnvConfig, RaceEnv
from drem_sim.learn.evaluate import drive
from drem_sim.learn.track_sets import TrackDirection, TrackSetError, closed_track_names, expand, hold_out
from drem_sim.tracks import load_track

pytestmark = pytest.mark.sim

REPO = Path(__file__).resolve().parents[2]
DREM = REPO / ".venv" / "bin" / "drem"
SAMPLE = REPO / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"


class OnceALapSaboteur:
    """The demonstrator, except that once per lap (at 80 % progress) it steers hard right off the track."""

    def __init__(self, track) -> None:  # noqa: ANN001
        self.teacher = Demonstrator(track)
        self.armed = True

    def __call__(self, _obs, params):  # noqa: ANN001, ANN204
        progress = float(params.get("progress", 0.0))
        if progress < 50.0:
            self.armed = True
        if self.armed and progress > 80.0:
            if params.get("is_offtrack"):
                self.armed = False
            else:
                return {"steering_angle": -30.0, "speed": 2.0}
        if params.get("is_offtrack"):
            self.armed = False
        return self.teacher.act(params)


def test_a_car_that_leaves_the_track_once_a_lap_completes_no_lap() -> None:
    track = load_track("reinvent_base")
    env = RaceEnv(track, EnvConfig(observe=False))
    saboteur = OnceALapSaboteur(track)
    metrics = drive(env, saboteur, attempts=3, seed=0, label="saboteur", track_name="reinvent_base")
    # It leaves the track before every crossing: whatever it drives from a put-back spot, no lap is whole.
    assert metrics.laps_completed == 0 and metrics.laps_completed_pct == 0.0, metrics.attempt_progress
    assert metrics.offtrack_count >= 3 and metrics.lap_times_s == [] and metrics.mean_lap_time_s is None
    assert all(p < 100.0 for p in metrics.attempt_progress), metrics.attempt_progress


class LeavesWhereItCannot:
    """The demonstrator, except that on every lap it starts on the line it steers off the track at half distance;
    put back there, it drives the rest of the way to the line clean (as a car does that can take the straight but
    never the bend it just left the track on). Its progress is the lap's, from the timing line at waypoint 0."""

    def __init__(self, track) -> None:  # noqa: ANN001
        self.track = track
        self.teacher = Demonstrator(track)
        self.last_steps = -1
        self.from_line = True

    def __call__(self, _obs, params):  # noqa: ANN001, ANN204
        steps = int(params.get("steps", 0))
        lap_progress = self.track.progress((float(params["x"]), float(params["y"])))
        if steps < self.last_steps:  # a new episode: where it was put back (or a start, on the line)
            self.from_line = lap_progress < 5.0
        elif lap_progress < 5.0:
            self.from_line = True  # crossed the line
        self.last_steps = steps
        if self.from_line and 50.0 < lap_progress < 90.0:
            return {"steering_angle": -30.0, "speed": 2.0}
        return self.teacher.act(params)


def test_a_lap_finished_from_where_the_car_was_put_back_is_no_completed_lap() -> None:
    track = load_track("reinvent_base")
    metrics = drive(RaceEnv(track, EnvConfig(observe=False)), LeavesWhereItCannot(track), attempts=3, seed=0,
                    label="half", track_name="reinvent_base")

    # Every lap from the line ends off the track at half distance; the stretches from the put-back spot to the line
    # are neither laps nor attempts.
    assert metrics.laps_completed == 0 and metrics.lap_times_s == [], metrics.attempt_progress
    assert metrics.offtrack_count == 3 and all(45.0 < p < 60.0 for p in metrics.attempt_progress)


def test_a_clean_driver_completes_every_lap_with_its_lap_times() -> None:
    track = load_track("reinvent_base")
    teacher = Demonstrator(track)
    metrics = drive(RaceEnv(track, EnvConfig(observe=False)), lambda _o, p: teacher.act(p), attempts=2, seed=0,
                    label="demonstrator", track_name="reinvent_base")
    assert metrics.laps_completed == 2 and metrics.offtrack_count == 0
    assert len(metrics.lap_times_s) == 2 and all(7.0 < t < 12.0 for t in metrics.lap_times_s)


def test_a_recorded_run_and_drem_sim_record_count_no_lap_finished_after_a_put_back(tmp_path: Path) -> None:
    """The simulator goes on counting the car round after a put-back (`env.laps`, the lap its rows are on), but a
    run's laps and lap times (metadata.json, `drem sim record`/`demo`, the drive page) are the whole laps only."""
    from drem_sim.runs import record_run

    track = load_track("reinvent_base")
    env = RaceEnv(track)
    run = record_run(env, OnceALapSaboteur(track), tmp_path, laps=2, driver="saboteur", max_steps=15 * 60)
    meta = json.loads((run / "metadata.json").read_text())
    assert env.laps == 2 and env.resets >= 2  # it came round twice, leaving the track at 80 % each time
    assert (meta["laps"], meta["lap_times_ms"], meta["resets"]) == (0, [], env.resets)

    teacher = Demonstrator(track)
    clean = RaceEnv(track)
    run = record_run(clean, lambda _o, p: teacher.act(p), tmp_path, laps=2, driver="demonstrator")
    meta = json.loads((run / "metadata.json").read_text())
    assert clean.resets == 0 and meta["laps"] == 2
    assert meta["lap_times_ms"] == [round(t * 1000) for t in clean.lap_times_s]  # from the line, crossing to crossing


def test_track_specs_expand_directions_and_hold_out_by_name() -> None:
    closed = closed_track_names()
    assert "reinvent_base" in closed and "Straight_track" not in closed  # open routes are never raced
    selection = expand(["all"], both_directions=True)
    assert len(selection) == 2 * len(closed)
    kept, held = hold_out(selection, ["reInvent2019_track", "reinvent_base:reverse"], both_directions=False)
    assert TrackDirection("reInvent2019_track") not in kept
    assert TrackDirection("reInvent2019_track", True) not in kept
    assert TrackDirection("reinvent_base") in kept and TrackDirection("reinvent_base", True) not in kept
    assert held == [TrackDirection("reInvent2019_track"), TrackDirection("reinvent_base", True)]
    with pytest.raises(TrackSetError, match="unknown track 'no_such_track'"):
        expand(["reinvent_base,no_such_track"])


def test_cli_eval_reports_each_track_and_direction(tmp_path: Path) -> None:
    out = tmp_path / "suite"
    done = subprocess.run([str(DREM), "sim", "eval", "--model", str(SAMPLE), "--track", "reinvent_base",
                           "--both-directions", "--laps", "1", "--out", str(out)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert any(line.startswith("reinvent_base ") for line in lines), done.stdout
    assert any(line.startswith("reinvent_base:reverse ") for line in lines), done.stdout
    suite = json.loads((out / "suite.json").read_text())
    assert [row["track"] for row in suite["tracks"]] == ["reinvent_base", "reinvent_base:reverse"]
    forward = json.loads((out / "metrics-reinvent_base.json").read_text())
    assert forward["attempts"] == 1 and forward["laps_completed"] == 1


def test_cli_eval_refuses_an_unknown_track_by_name(tmp_path: Path) -> None:
    done = subprocess.run([str(DREM), "sim", "eval", "--model", str(SAMPLE), "--track", "reinvent_base,nowhere"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "unknown track 'nowhere'" in done.stderr


def test_cli_eval_of_a_track_file_driven_the_other_way_writes_its_metrics(tmp_path: Path) -> None:
    """`--track some/file.npy:reverse --out D`: the table, then one metrics file named after the track, not a path."""
    import shutil

    from drem_sim.tracks import PACKAGE_TRACKS_DIR

    venue = tmp_path / "venue:2 tracks"  # a colon in a folder's name is no direction
    venue.mkdir()
    shutil.copy(PACKAGE_TRACKS_DIR / "reinvent_base.npy", venue / "hall_b.npy")
    out = tmp_path / "out"
    done = subprocess.run([str(DREM), "sim", "eval", "--model", str(SAMPLE), "--track", f"{venue}/hall_b.npy:reverse",
                           "--laps", "1", "--out", str(out)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert json.loads((out / "metrics-hall_b-reverse.json").read_text())["attempts"] == 1
    assert json.loads((out / "suite.json").read_text())["tracks"][0]["track"].endswith("hall_b.npy:reverse")
