from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from drem_cars.model_files import ConsoleModelError, ModelError
from drem_cars.parts.drive_mapping import ActionToDrive, unit_throttle
from drem_cars.parts.pilot_onnx import OnnxPilot, preprocess
from tests.cars.onnx_models import CONTINUOUS_SPACE, DISCRETE_ACTIONS, frame, mean_brightness_policy, model_dir

pytestmark = pytest.mark.unit


def test_discrete_model_takes_the_argmax_action(tmp_path: Path) -> None:
    # scores: [mean/255·(-1)+1, 0.6, mean/255] → dark frame picks action 0, bright frame action 2
    onnx_bytes = mean_brightness_policy([-1 / 255, 0.0, 1 / 255], [1.0, 0.6, 0.0])
    pilot = OnnxPilot(model_dir(tmp_path / "d", onnx_bytes, {"action_space": DISCRETE_ACTIONS,
                                                              "action_space_type": "discrete"}))
    steering, speed, latency = pilot.run(frame(0))
    assert (steering, speed) == (-30.0, 0.6)
    assert pilot.run(frame(255))[:2] == (30.0, 0.6)
    assert pilot.run(frame(128))[:2] == (0.0, 1.2), "mid grey: the constant 0.6 score wins"
    assert latency is not None and latency > 0


def test_continuous_model_clips_and_rescales_to_low_high(tmp_path: Path) -> None:
    # raw pixel values reach the graph (0..255), so mean/127.5 - 1 spans [-1, 1]; ×3 pushes beyond, then clipped
    onnx_bytes = mean_brightness_policy([3 / 127.5, 1 / 127.5], [-3.0, -1.0])
    pilot = OnnxPilot(model_dir(tmp_path / "c", onnx_bytes, {"action_space": CONTINUOUS_SPACE,
                                                              "action_space_type": "continuous"}))
    assert pilot.run(frame(255))[:2] == pytest.approx((30.0, 2.0))
    assert pilot.run(frame(0))[:2] == pytest.approx((-30.0, 0.5))
    steering, speed, _ = pilot.run(frame(127))
    assert steering == pytest.approx(-30 + (3 * 127 / 127.5 - 3 + 1) * 30, abs=0.01)
    assert speed == pytest.approx(0.5 + (127 / 127.5 - 1 + 1) * 0.75, abs=0.01)


def test_colour_frames_of_any_size_become_grayscale_nhwc_raw_values() -> None:
    bgr = np.zeros((480, 640, 3), dtype=np.uint8)
    bgr[..., 2] = 255  # pure red
    tensor = preprocess(bgr)
    assert tensor.shape == (1, 120, 160, 1) and tensor.dtype == np.float32
    assert tensor.max() == pytest.approx(76, abs=1), "raw 0..255 luma of red, not normalised"


def test_a_console_tensorflow_model_gets_a_clear_message(tmp_path: Path) -> None:
    folder = tmp_path / "console"
    (folder / "agent").mkdir(parents=True)
    (folder / "agent" / "model.pb").write_bytes(b"frozen graph")
    (folder / "model_metadata.json").write_text(json.dumps({"action_space": DISCRETE_ACTIONS}))
    with pytest.raises(ConsoleModelError, match="TensorFlow.*ONNX models only"):
        OnnxPilot(folder)


def test_a_model_whose_outputs_do_not_match_the_action_list_is_refused(tmp_path: Path) -> None:
    pilot = OnnxPilot(model_dir(tmp_path / "m", mean_brightness_policy([0.0, 0.0], [0.0, 1.0]),
                                {"action_space": DISCRETE_ACTIONS}))
    with pytest.raises(ModelError, match="outputs 2 values but the action space lists 3"):
        pilot.run(frame(10))


def test_deepracer_speed_curve_and_steering_normalisation() -> None:
    assert unit_throttle(2.0, 2.0) == pytest.approx(1.0)
    assert unit_throttle(1.0, 2.0) == pytest.approx(0.8)
    mapping = ActionToDrive(lambda: None)
    assert mapping.run(10.0, 1.0) == (0.0, 0.0), "no model loaded: no motion"


def test_continuous_steering_is_divided_by_high_as_the_cars_navigation_node_does() -> None:
    """deepracer_navigation_node.py: the continuous scale is `high`, whatever `low` is; here |low| > |high|."""
    from drem_cars.model_files import action_space_of

    space = action_space_of({"action_space_type": "continuous",
                             "action_space": {"steering_angle": {"low": -30, "high": 20}, "speed": {"low": 0.5,
                                                                                                   "high": 2.0}}})
    mapping = ActionToDrive(lambda: space)
    assert mapping.run(10.0, 2.0) == (pytest.approx(0.5), pytest.approx(1.0)), "10 / high 20, not 10 / |low| 30"
    assert mapping.run(-30.0, 1.0)[0] == -1.0, "-30 / 20 goes past full lock: held at the servo's -1"
    discrete = action_space_of({"action_space": [{"steering_angle": -30, "speed": 1.0},
                                                 {"steering_angle": 15, "speed": 2.0}]})
    assert ActionToDrive(lambda: discrete).run(15.0, 1.0) == (pytest.approx(0.5), pytest.approx(0.8))


def test_a_converted_console_model_drives_the_car_agent_like_the_console_graph(tmp_path: Path) -> None:
    """The real-structure console graph, converted: raw 0..255 frames in, argmax over its 9 actions out."""
    from drem_sim.console.convert import convert
    from tests import console_fixture

    files = console_fixture.members()
    metadata = json.loads(files["model_metadata.json"])
    (tmp_path / "model.pb").write_bytes(files["agent/model.pb"])
    folder = tmp_path / "console-model"
    folder.mkdir()
    assert convert(tmp_path / "model.pb", metadata, folder / "model.onnx").outcome == "converted"
    (folder / "model_metadata.json").write_text(json.dumps(metadata))

    pilot = OnnxPilot(folder)
    frames = np.load(console_fixture.FRAMES)
    expected = np.load(console_fixture.EXPECTED)
    for camera_frame, probabilities in zip(frames, expected, strict=True):
        chosen = metadata["action_space"][int(np.argmax(probabilities))]
        steering, speed, _ = pilot.run(camera_frame[:, :, 0])
        assert (steering, speed) == (chosen["steering_angle"], chosen["speed"])
