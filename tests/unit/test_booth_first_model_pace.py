"""The booth's first model drives like its visitor: a keyboard visitor taps ↑ (slow in the bends, quicker on the
straights, letting go often), the booth records the drive, v0001 is trained on it exactly as the booth worker trains
(the booth's default 8 epochs), and v0001 laps the visitor's track at the visitor's pace.

The measure: v0001's mean lap time over 3 laps divided by the mean of the visitor's 4 laps (1.0 = the same pace). Before
the speed labels came from the car's real speed, frames with ↑ released were dropped and the rest taught 3.0 m/s:
v0001 drove flat out (6 s laps against the visitor's 35-44 s).

The visitor steers smoothly (a stick or touch; the keyboard's full-lock taps are another problem than speed), and the
throttle is the keyboard's: ↑ held (full) or released (nothing)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from chalicelib.domain.booth_drive import DriveControl, LiveDrive
from chalicelib.domain.booth_runs import RunMode, RunRecord, RunStatus
from drem_sim.demonstrator import Demonstrator, DemonstratorConfig
from drem_sim.env import RaceEnv
from drem_sim.learn.evaluate import drive
from drem_sim.learn.pilot import OnnxPilot
from drem_sim.learn.pipeline import train_to_archive
from drem_sim.learn.train import TrainConfig

pytestmark = pytest.mark.unit

TRACK = "drem_oval"
VISITOR_PACE = 0.55  # of the demonstrator's speed profile: 0.45 m/s in the bends to 1.2 m/s on the straights
BOOTH_EPOCHS = 8  # chalicelib.domain.booth_training.NewJob's default


def visitor_drive(folder: Path, laps: int) -> tuple[Path, list[float], float]:
    record = RunRecord(run_id="0123456789ab", owner_sub="sub-v", owner_username="visitor", track_id=TRACK,
                       mode=RunMode.MANUAL, status=RunStatus.RECORDING, created_at="2026-11-27T00:00:00Z",
                       prefix="runs/x/")
    car = LiveDrive(record, folder)
    # Where the visitor looks (the line ahead, how fast a bend can be taken), with a person's unsteady hand.
    eyes = Demonstrator(car.env.track, DemonstratorConfig(steering_noise_deg=3.0), rng=np.random.default_rng(1))
    state = car.state()
    released = 0
    while state["laps"] < laps and state["frames"] < 15 * 60 * laps:
        wanted = eyes.act(car.params)
        up = state["speed"] < VISITOR_PACE * wanted["speed"]  # the speed shown on the drive page
        released += not up
        state = car.step(DriveControl(steering=wanted["steering_angle"] / 30.0, throttle=1.0 if up else 0.0))
    return car.close(), state["lap_times_s"], released / state["frames"]


def test_the_first_model_laps_at_the_visitors_pace(tmp_path: Path) -> None:
    run, visitor_laps, released_share = visitor_drive(tmp_path / "drive", laps=4)
    assert len(visitor_laps) == 4 and released_share > 0.3  # the visitor let go of ↑ often

    trained = train_to_archive([run], tmp_path / "model", "v0001",
                               TrainConfig(epochs=BOOTH_EPOCHS, seed=0, batch_size=32, num_threads=1), progress=None)
    assert trained.snapshot.manifest["runs"][0]["frames_used"] >= 0.95 * trained.snapshot.manifest["runs"][0]["rows"]
    pilot = OnnxPilot.from_archive(trained.archive)
    laps = drive(RaceEnv(TRACK), lambda observation, _params: pilot.act(observation), 3, 0, "v0001", TRACK)

    visitor_mean = sum(visitor_laps) / len(visitor_laps)
    assert laps.laps_completed == 3, laps.summary()
    assert laps.mean_lap_time_s is not None
    ratio = laps.mean_lap_time_s / visitor_mean
    print(f"lap time ratio v0001/visitor {ratio:.3f} ({laps.mean_lap_time_s:.2f}s / {visitor_mean:.2f}s)")
    assert 0.8 <= ratio <= 1.25, f"v0001 {laps.mean_lap_time_s:.1f}s a lap, the visitor {visitor_mean:.1f}s"
