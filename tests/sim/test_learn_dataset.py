"""Dataset snapshots keep the examples worth learning: on the track, and what the driver really did."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drem_sim.learn.dataset import MIN_MODEL_SPEED, load_snapshot
from drem_sim.runs import RunRecorder

pytestmark = pytest.mark.sim


def test_a_persons_drive_teaches_the_cars_real_speed_and_keeps_the_frames_where_up_was_released(
        tmp_path: Path) -> None:
    recorder = RunRecorder(tmp_path, "drem_oval", direction="forward", driver="human", seed=None)
    params = {"progress": 1.0, "x": 0.0, "y": 0.0, "heading": 0.0}
    # (command, car speed): standing at the line, ↑ held, ↑ released (the car slows, then stops), ↑ again, off-track
    drive = [(0.0, 0.0), (3.0, 0.4), (3.0, 0.8), (0.0, 0.27), (0.0, 0.0), (3.0, 0.4), (3.0, 0.0)]
    for index, (command, car_speed) in enumerate(drive):
        recorder.add(np.full((120, 160), 40 + index, np.uint8), {"steering_angle": 1.0 * index, "speed": command},
                     params, t_ms=index * 67, lap=0, offtrack=index == 6, car_speed=car_speed)
    snapshot = load_snapshot([recorder.close(laps=0, lap_times_ms=[])])

    assert snapshot.speed.tolist() == pytest.approx([0.4, 0.8, 0.27, 0.0, 0.4])  # nothing dropped for a released ↑
    assert snapshot.steering.tolist() == pytest.approx([1.0, 2.0, 3.0, 4.0, 5.0])  # not before setting off
    assert snapshot.scale.speed_low == pytest.approx(MIN_MODEL_SPEED)  # a stop teaches "slowest", never "stand"
    assert snapshot.scale.speed_high == pytest.approx(0.8)


def test_a_programs_offtrack_and_standing_still_frames_are_left_out(tmp_path: Path) -> None:
    recorder = RunRecorder(tmp_path, "drem_oval", direction="forward", driver="human", seed=None)
    params = {"progress": 1.0, "x": 0.0, "y": 0.0, "heading": 0.0}
    for index, (speed, offtrack) in enumerate([(0.0, False), (1.5, False), (2.0, True), (1.8, False)]):
        frame = np.full((120, 160), 40 + index, np.uint8)
        recorder.add(frame, {"steering_angle": 5.0 * index, "speed": speed}, params, t_ms=index * 67, lap=0,
                     offtrack=offtrack)
    run_dir = recorder.close(laps=0, lap_times_ms=[])

    snapshot = load_snapshot([run_dir])

    assert len(snapshot) == 2
    assert snapshot.speed.tolist() == pytest.approx([1.5, 1.8])
    assert snapshot.steering.tolist() == pytest.approx([5.0, 15.0])
    assert [int(image[0, 0]) for image in snapshot.images] == [41, 43]
    assert snapshot.manifest["runs"][0]["rows"] == 4 and snapshot.manifest["runs"][0]["frames_used"] == 2
