"""What a visitor reads on the drive page and on the saved run's page agrees: one lap count under one name, the
car's own speed, speed ticks that say different things, and a steering plot that shows every full-lock burst."""
from __future__ import annotations

import json
import re
from html import unescape
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from chalicelib.domain.booth_drive import DriveControl, LiveDrive
from chalicelib.domain.booth_runs import RunMode, RunRecord, RunStatus, compute_metrics, parse_controls
from chalicelib.views.booth_views import run_inspection
from drem_sim.demonstrator import Demonstrator

pytestmark = pytest.mark.unit


def record(track: str = "drem_oval") -> RunRecord:
    return RunRecord(run_id="0123456789ab", owner_sub="sub-v", owner_username="visitor", track_id=track,
                     mode=RunMode.MANUAL, status=RunStatus.FINALISED, created_at="2026-11-27T00:00:00Z",
                     prefix="runs/x/")


def test_the_drive_page_counts_laps_and_attempts_as_the_run_page_will(tmp_path: Path) -> None:
    car = LiveDrive(record(), tmp_path)
    eyes = Demonstrator(car.env.track)

    def steer(throttle: float = 0.5) -> dict[str, Any]:
        return car.step(DriveControl(steering=eyes.act(car.params)["steering_angle"] / 30.0, throttle=throttle))

    state = car.state()
    while state["laps_completed"] < 1:  # a clean lap from the standing start
        state = steer()
    while state["resets"] < 1:  # then off the track, full lock right at full speed
        state = car.step(DriveControl(steering=-1.0, throttle=1.0))
    assert state["speed"] == 0.0  # put back at rest, with ↑ held: the page shows the car's speed, not "3 m/s"
    laps_before = state["laps"]
    while state["laps"] == laps_before:  # from where the car was put back, over the line: no lap, no attempt
        state = steer()
    for _ in range(15):
        state = steer()
    rows = parse_controls((car.close() / "controls.jsonl").read_bytes())
    metrics = compute_metrics(rows)

    assert (state["laps_completed"], state["attempts"]) == (metrics.laps_completed, metrics.attempts) == (1, 3)
    assert state["laps"] == 2  # the simulator's own count, which the page used to show as "Laps 2"
    assert state["speed"] == pytest.approx(car.env.car_state()["speed"], abs=0.01)


def rows_of(count: int, steering: Any, speed: float = 3.0) -> list[dict[str, Any]]:
    return [{"t_ms": i * 1000 // 15, "steering_angle": float(steering(i)), "speed": speed, "progress": 1.0,
             "x": 0.0, "y": 0.0, "lap": 0, "offtrack": False} for i in range(count)]


def test_a_constant_speed_has_ticks_that_say_different_things_where_they_are() -> None:
    plots = run_inspection(record(), rows_of(1787, lambda _i: 0.0, speed=3.0))
    ticks = re.findall(r'<text x="52" y="([0-9.]+)" text-anchor="end" class="plot-tick">([^<]*)</text>',
                       str(plots.speed_plot))
    values = [float(label) for _, label in ticks]
    assert len(values) >= 4 and len({label for _, label in ticks}) == len(ticks), ticks  # never all "3"
    assert min(values) < 3.0 < max(values)
    # Each label is the value its gridline stands at: the heights fall on one straight line through the values.
    (y0, v0), (y1, v1) = (float(ticks[0][0]), values[0]), (float(ticks[-1][0]), values[-1])
    for (y, _), value in zip(ticks, values, strict=True):
        assert abs(y0 + (y1 - y0) * (value - v0) / (v1 - v0) - float(y)) < 0.2, ticks


def test_the_speed_plot_names_the_speed_commanded_when_the_run_did_not_measure_it() -> None:
    autonomous = run_inspection(record(), rows_of(60, lambda _i: 0.0, speed=2.0))  # a model's run: commands only
    assert "The speed commanded over the run" in str(autonomous.speed_plot) and not autonomous.speed_measured
    rows = rows_of(60, lambda _i: 0.0, speed=2.0)
    for row in rows:
        row["car_speed"] = 1.5
    measured = run_inspection(record(), rows)
    assert "The car&#39;s speed over the run" in str(measured.speed_plot) and measured.speed_measured


def test_the_steering_plot_shows_a_burst_between_samples() -> None:
    # 40 frames at full right lock in the middle of a 1,787-frame drive: a sample every 30th frame missed them.
    burst = range(901, 941)
    plots = run_inspection(record(), rows_of(1787, lambda i: -30.0 if i in burst else 2.0))
    shown = [float(v) for v in re.findall(r"steering °: (-?[0-9.]+)</title>", str(plots.steering_plot))]
    assert min(shown) == -30.0 and max(shown) == 2.0


def test_the_speed_plot_shows_the_cars_speed_when_the_run_recorded_it() -> None:
    rows = rows_of(60, lambda _i: 0.0, speed=3.0)
    for index, row in enumerate(rows):
        row["car_speed"] = min(3.0, 0.4 * index)
    shown = [float(v) for v in re.findall(r"speed m/s: ([0-9.]+)</title>",
                                           str(run_inspection(record(), json.loads(json.dumps(rows))).speed_plot))]
    assert min(shown) == 0.0 and max(shown) == 3.0
    assert np.isclose(compute_metrics(rows).mean_speed, np.mean([r["car_speed"] for r in rows]), atol=0.001)


def test_the_drive_and_run_pages_name_the_speed_they_show_as_the_cars(alice: Any, client: Any) -> None:
    headers = {"Authorization": alice.headers["Authorization"]}
    driving = unescape(client.http.get("/booth/drive/drem_oval", headers=headers).body.decode())
    assert "<dt>Car's speed</dt>" in driving  # measured, not the 3 m/s that ↑ commands
    run_id = alice.call("POST", "/api/drive", {"track_id": "drem_oval"}).json_body["run_id"]
    for _ in range(20):
        assert alice.call("POST", f"/api/runs/{run_id}/drive", {"steering": 0.0, "throttle": 0.6}).status_code == 200
    assert alice.call("POST", f"/api/runs/{run_id}/drive/finish").status_code == 200
    page = unescape(client.http.get(f"/booth/runs/{run_id}", headers=headers).body.decode())
    assert "<dt>Car's mean speed</dt>" in page and "The car's speed over the run" in page
