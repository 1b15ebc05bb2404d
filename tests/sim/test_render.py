"""Human-facing pictures: a track map with the driven path, and an MP4 of a recorded run."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from drem_sim.demonstrator import Demonstrator
from drem_sim.env import EnvConfig, RaceEnv
from drem_sim.render import PATH_COLOUR, run_video, save_track_png
from drem_sim.runs import record_run
from drem_sim.tracks import load_track

pytestmark = pytest.mark.sim


def test_track_map_shows_the_driven_path(tmp_path) -> None:
    track = load_track("reinvent_base")
    path = [track.pose_at(s)[:2] for s in np.linspace(0.0, 8.0, 80)]
    image = cv2.imread(str(save_track_png(track, tmp_path / "map.png", path, px_per_m=50)))
    x0, y0, x1, y1 = track.bounds
    assert image.shape[1] == pytest.approx((x1 - x0 + 1.0) * 50, abs=2)
    red = np.all(np.abs(image.astype(int) - PATH_COLOUR) < 40, axis=-1)
    assert red.sum() > 8.0 * 50  # about 8 m of path, a couple of pixels thick
    plain = cv2.imread(str(save_track_png(track, tmp_path / "plain.png", None, px_per_m=50)))
    assert not np.all(np.abs(plain.astype(int) - PATH_COLOUR) < 40, axis=-1).any()


def test_run_video_has_one_frame_per_recorded_frame(tmp_path) -> None:
    env = RaceEnv("drem_oval", EnvConfig(max_steps=30))
    driver = Demonstrator(env.track)
    run_dir = record_run(env, lambda _o, p: driver.act(p), tmp_path / "runs", laps=1, driver="demonstrator")
    video = run_video(run_dir, tmp_path / "run.mp4", scale=2)
    capture = cv2.VideoCapture(str(video))
    try:
        assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == 30
        ok, frame = capture.read()
        assert ok and frame.shape == (240, 320, 3)
    finally:
        capture.release()
