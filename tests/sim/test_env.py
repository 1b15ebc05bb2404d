"""RaceEnv: camera observations, DeepRacer params, off-track resets, lap counting, seeding."""
from __future__ import annotations

import numpy as np
import pytest

from drem_sim.camera import CameraConfig
from drem_sim.demonstrator import Demonstrator
from drem_sim.env import EnvConfig, RaceEnv
from drem_sim.tracks import load_track

pytestmark = pytest.mark.sim

PARAM_KEYS = {"all_wheels_on_track", "x", "y", "heading", "distance_from_center", "is_left_of_center", "progress",
              "steps", "speed", "steering_angle", "track_width", "track_length", "waypoints", "closest_waypoints",
              "projection_distance", "is_reversed", "is_offtrack", "is_crashed", "sim_time"}


def test_observation_is_a_160x120_grayscale_frame_showing_both_white_borders() -> None:
    env = RaceEnv("reinvent_base")
    obs, info = env.reset(seed=0)
    assert obs.shape == (120, 160) and obs.dtype == np.uint8
    ground = obs[30:]  # below the horizon
    white = ground > 200
    assert white[:, :80].sum() > 20 and white[:, 80:].sum() > 20  # a border on each side of the road
    assert (obs[80:] < 60).mean() > 0.4  # mostly dark road just ahead
    assert (obs[:20] > 150).all()  # sky above the horizon
    assert info["laps"] == 0 and info["resets"] == 0


def test_same_seed_gives_identical_frames_even_with_sensor_noise() -> None:
    config = EnvConfig(camera=CameraConfig(noise_std=4.0, brightness_jitter=0.1))
    frames = []
    for seed in (5, 5, 6):
        env = RaceEnv("drem_oval", config)
        env.reset(seed=seed)
        obs = None
        for _ in range(10):
            obs, *_ = env.step({"steering_angle": 3.0, "speed": 1.0})
        frames.append(obs)
    assert np.array_equal(frames[0], frames[1])
    assert not np.array_equal(frames[0], frames[2])


def test_params_hold_the_deepracer_reward_inputs() -> None:
    env = RaceEnv("reinvent_base", EnvConfig(observe=False))
    env.reset(seed=0)
    _, params, terminated, truncated, info = env.step((5.0, 1.5))  # a 2-sequence action works too
    assert set(params) == PARAM_KEYS and info["params"] is params
    assert params["steering_angle"] == 5.0 and params["speed"] == 1.5
    assert params["steps"] == 1 and params["sim_time"] == pytest.approx(1 / 15)
    assert params["track_length"] == pytest.approx(17.71, abs=0.05)
    assert params["track_width"] == pytest.approx(0.762, abs=0.01)
    assert len(params["waypoints"]) == env.track.n_waypoints
    prev, nxt = params["closest_waypoints"]
    assert nxt == (prev + 1) % env.track.n_waypoints
    assert 0 < params["progress"] < 1 and params["all_wheels_on_track"] and not params["is_offtrack"]
    assert -180 < params["heading"] <= 180 and not params["is_reversed"] and not params["is_crashed"]
    assert not terminated and not truncated


def test_commands_are_clipped_to_the_car_limits() -> None:
    env = RaceEnv("drem_oval", EnvConfig(observe=False))
    env.reset(seed=0)
    _, params, *_ = env.step({"steering_angle": 90.0, "speed": 12.0})
    assert params["steering_angle"] == 30.0 and params["speed"] == 4.0


def test_a_bad_action_is_a_clear_error() -> None:
    env = RaceEnv("drem_oval", EnvConfig(observe=False))
    env.reset()
    with pytest.raises(ValueError, match="steering_angle"):
        env.step({"speed": 1.0})
    with pytest.raises(ValueError, match="2|values"):
        env.step([1.0, 2.0, 3.0])


def test_driving_straight_into_a_bend_goes_off_track_and_is_put_back() -> None:
    env = RaceEnv("drem_oval", EnvConfig(observe=False, max_resets=2, max_steps=600))
    env.reset(seed=0)
    went_off, resets_seen, done, steps = None, [], False, 0
    while not done:
        _, params, terminated, truncated, info = env.step({"steering_angle": 0.0, "speed": 2.0})
        steps += 1
        if params["is_offtrack"] and went_off is None:
            went_off = params
        resets_seen.append(info["resets"])
        done = terminated or truncated
    assert went_off is not None and terminated and not truncated
    assert info["resets"] == 2 and info["laps"] == 0
    # Put back on the centre line: the next frame has the car on track again.
    first = resets_seen.index(1)
    assert went_off["progress"] > 15  # it reached the first bend (the oval's straight is ~23% of the lap)
    _, params, *_ = env.step({"steering_angle": 0.0, "speed": 0.0})
    assert params["all_wheels_on_track"] and params["distance_from_center"] < 0.05
    assert first < steps


def test_laps_are_counted_with_their_times() -> None:
    env = RaceEnv("drem_chicane", EnvConfig(observe=False, max_laps=2))
    driver = Demonstrator(env.track)
    _, info = env.reset(seed=1)
    params, done, completed_at = info["params"], False, []
    while not done:
        _, params, terminated, truncated, info = env.step(driver.act(params))
        if info["lap_completed"]:
            completed_at.append(info["sim_time"])
        done = terminated or truncated
    assert info["laps"] == 2 and len(info["lap_times_s"]) == 2
    assert sum(info["lap_times_s"]) == pytest.approx(completed_at[-1], abs=1 / 15)
    assert params["progress"] < 5  # a new lap has just begun


def test_max_steps_truncates_and_reset_starts_over() -> None:
    env = RaceEnv("reinvent_base", EnvConfig(observe=False, max_steps=3))
    env.reset(seed=0)
    results = [env.step({"steering_angle": 0.0, "speed": 1.0}) for _ in range(3)]
    assert [r[3] for r in results] == [False, False, True]
    _, info = env.reset(seed=0)
    assert info["params"]["steps"] == 0 and info["sim_time"] == 0.0


def test_random_start_comes_from_the_seed() -> None:
    env = RaceEnv("reinvent_base", EnvConfig(observe=False, random_start=True))
    starts = []
    for seed in (1, 1, 2):
        _, info = env.reset(seed=seed)
        starts.append(info["params"]["projection_distance"])
    assert starts[0] == starts[1] != starts[2]


def test_reversed_track_reports_is_reversed_and_side_relative_to_driving() -> None:
    forward = RaceEnv("drem_oval", EnvConfig(observe=False, start_offset_m=2.0))
    backward = RaceEnv(load_track("drem_oval", reverse=True), EnvConfig(observe=False))
    forward.reset(seed=0)
    backward.reset(seed=0)
    _, params_f, *_ = forward.step({"steering_angle": 20.0, "speed": 1.0})  # drift to the left
    _, params_b, *_ = backward.step({"steering_angle": 20.0, "speed": 1.0})
    assert params_b["is_reversed"] and not params_f["is_reversed"]
    assert params_f["is_left_of_center"] and params_b["is_left_of_center"]
