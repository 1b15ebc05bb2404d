"""Dataset snapshots keep only examples worth learning: on the track and moving."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drem_sim.learn.dataset import load_snapshot
from drem_sim.runs import RunRecorder

pytestmark = pytest.mark.sim


def test_offtrack_and_standing_still_frames_are_left_out(tmp_path: Path) -> None:
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
