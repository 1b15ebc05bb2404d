"""The camera sensor: a deterministic function of the pose (and of the seeded noise)."""
from __future__ import annotations

import numpy as np
import pytest

from drem_sim.camera import BORDER, Camera, CameraConfig
from drem_sim.tracks import load_track
from tests.sim.camera_reference import REFERENCE_FILE, TRACKS, reference_poses

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def camera() -> Camera:
    return Camera(load_track("reinvent_base"))


def test_same_pose_same_frame_and_moving_changes_it(camera: Camera) -> None:
    x, y, heading = camera_pose = load_track("reinvent_base").pose_at(2.0)
    first = camera.render(*camera_pose)
    again = camera.render(x, y, heading)
    assert np.array_equal(first, again) and first is not again
    turned = camera.render(x, y, heading + 0.3)
    assert np.abs(first.astype(int) - turned.astype(int)).mean() > 5


def test_facing_off_the_track_sees_no_road_ahead(camera: Camera) -> None:
    x, y, heading = load_track("reinvent_base").pose_at(2.0)
    on_road = camera.render(x, y, heading)
    away = camera.render(x, y, heading + np.pi / 2)  # looking across the track, out to the grass
    assert (on_road[90:] < 60).mean() > 0.5
    assert (away[60:] < 60).mean() < (on_road[60:] < 60).mean()


def test_seeded_noise_is_reproducible() -> None:
    track = load_track("drem_oval")
    camera = Camera(track, CameraConfig(noise_std=5.0, brightness_jitter=0.1))
    pose = track.pose_at(1.0)
    a = camera.render(*pose, rng=np.random.default_rng(9))
    b = camera.render(*pose, rng=np.random.default_rng(9))
    c = camera.render(*pose, rng=np.random.default_rng(10))
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_borders_are_drawn_white_on_the_texture(camera: Camera) -> None:
    assert (camera.texture.image >= BORDER - 5).sum() > 1000


@pytest.mark.parametrize("track_name", TRACKS)
def test_frames_are_the_ones_the_sample_models_were_trained_on(track_name: str) -> None:
    """The renderer draws what it drew before issue 33's speed work (saved frames): at most one grey level apart,
    on almost no pixels (float rounding of the warp's coordinates), at poses on the road, near the borders and
    looking out over the grass where the texture ends."""
    saved = np.load(REFERENCE_FILE)[track_name]
    camera = Camera(load_track(track_name))
    for pose, before in zip(reference_poses(track_name), saved, strict=True):
        now = camera.render(*pose)
        difference = np.abs(now.astype(int) - before.astype(int))
        assert difference.max() <= 1, pose
        assert (difference > 0).mean() < 0.002, pose
