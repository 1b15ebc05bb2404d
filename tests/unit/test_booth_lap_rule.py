"""One lap rule everywhere: a booth run's figures (read from its recorded rows) are the figures `drem sim eval` and
scrutineering give for the same driving (stepping the simulator), and a 1-lap autonomous run shows the lap it drove."""
from __future__ import annotations

from pathlib import Path

import pytest

from chalicelib.domain.booth_runs import RunMetrics, compute_metrics, parse_controls
from drem_sim.demonstrator import Demonstrator, DemonstratorConfig
from drem_sim.env import RaceEnv
from drem_sim.learn.evaluate import EvalMetrics, drive
from drem_sim.runs import record_run

pytestmark = pytest.mark.unit

TRACK = "reinvent_base"
SAMPLE = Path(__file__).resolve().parents[2] / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"
CAREFUL = DemonstratorConfig(lateral_accel=9.0, max_speed=4.0, min_speed=2.0)
TOO_FAST = DemonstratorConfig(lateral_accel=15.0, max_speed=3.5, min_speed=1.0)  # slides off in the hairpin


def run_and_eval(tmp_path: Path, config: DemonstratorConfig, laps: int) -> tuple[RunMetrics, EvalMetrics]:
    env = RaceEnv(TRACK)
    driver = Demonstrator(env.track, config)
    run = record_run(env, lambda _obs, params: driver.act(params), tmp_path, laps=laps, driver="x",
                     max_steps=15 * 40 * laps)  # the booth worker's autonomous run
    metrics = compute_metrics(parse_controls((run / "controls.jsonl").read_bytes()))
    evaluated = drive(RaceEnv(TRACK), lambda _obs, params: driver.act(params), metrics.attempts, 0, "x", TRACK)
    return metrics, evaluated


def test_a_one_lap_autonomous_run_shows_the_lap_the_car_drove(tmp_path: Path) -> None:
    metrics, evaluated = run_and_eval(tmp_path, CAREFUL, laps=1)
    assert evaluated.laps_completed == 1  # `drem sim eval` laps it, and so does the run
    assert (metrics.laps_completed, metrics.attempts, metrics.completion_pct) == (1, 1, 100.0)
    assert metrics.lap_times_s == pytest.approx(evaluated.lap_times_s, abs=0.07)  # within one decision


def test_completion_after_an_off_track_is_what_evaluation_and_scrutineering_say(tmp_path: Path) -> None:
    metrics, evaluated = run_and_eval(tmp_path, TOO_FAST, laps=3)
    assert metrics.offtrack_count >= 3 and metrics.laps_completed == evaluated.laps_completed == 0
    # The stretch from where the car was put back to the line is no attempt: it used to lift the run's figure to
    # ~80 % where scrutineering of the same driving said ~35 %.
    assert metrics.attempts == evaluated.attempts
    assert metrics.completion_pct == pytest.approx(evaluated.completion_pct, abs=0.5)
    assert metrics.completion_pct < 50


def test_a_one_lap_autonomous_run_of_a_model_that_laps_shows_one_of_one(tmp_path: Path) -> None:
    """The booth worker's autonomous run of a model (the shipped sample ONNX model, which `drem sim eval` laps on its
    track) shows the lap it drove: 1 of 1, not 0 of 1."""
    from drem_sim.learn.pilot import OnnxPilot

    pilot = OnnxPilot.from_archive(SAMPLE)
    run = record_run(RaceEnv(TRACK), lambda observation, _params: pilot.act(observation), tmp_path, laps=1,
                     driver="model:sample", max_steps=15 * 40)
    metrics = compute_metrics(parse_controls((run / "controls.jsonl").read_bytes()))
    assert (metrics.laps_completed, metrics.attempts, metrics.completion_pct) == (1, 1, 100.0)
    assert metrics.best_lap_s is not None and 7.0 < metrics.best_lap_s < 12.0


def test_a_model_that_leaves_at_the_same_bend_gets_the_same_figures_on_the_run_page_and_from_scrutineering(
        tmp_path: Path) -> None:
    """The shipped sample model leaves reInvent2019_track at the same bend near the finish on every lap (docs/
    learning.md §6): its booth run and its scrutineering on that track say the same laps (none) and completion."""
    from drem_sim.learn.pilot import OnnxPilot
    from drem_sim.learn.scrutineer import scrutineer

    pilot = OnnxPilot.from_archive(SAMPLE)
    run = record_run(RaceEnv("reInvent2019_track"), lambda observation, _params: pilot.act(observation), tmp_path,
                     laps=2, driver="model:sample", max_steps=15 * 40 * 2)
    shown = compute_metrics(parse_controls((run / "controls.jsonl").read_bytes()))
    report = scrutineer(SAMPLE, "reInvent2019_track", laps=shown.attempts)

    assert shown.offtrack_count >= 2 and shown.laps_completed == report.laps_completed == 0
    assert report.attempts == shown.attempts == 2
    assert report.completion_pct is not None and report.completion_pct < 100.0
    assert shown.completion_pct == pytest.approx(report.completion_pct, abs=1.0)
