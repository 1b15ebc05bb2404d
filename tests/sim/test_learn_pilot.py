"""OnnxPilot maps real ONNX outputs to actions the way the metadata says (continuous and discrete)."""
from __future__ import annotations

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper

from drem_sim.learn.package import ArchiveError
from drem_sim.learn.pilot import OnnxPilot

pytestmark = pytest.mark.sim


def _constant_policy(values: list[float]) -> bytes:
    """A real ONNX graph that ignores the camera frame and always outputs ``values``."""
    observation = helper.make_tensor_value_info("observation", TensorProto.FLOAT, [1, 120, 160, 1])
    policy = helper.make_tensor_value_info("policy", TensorProto.FLOAT, [1, len(values)])
    nodes = [
        helper.make_node("ReduceSum", ["observation"], ["total"], keepdims=0),
        helper.make_node("Mul", ["total", "zero"], ["nothing"]),
        helper.make_node("Add", ["constant", "nothing"], ["policy"]),
    ]
    initialisers = [helper.make_tensor("zero", TensorProto.FLOAT, [], [0.0]),
                    helper.make_tensor("constant", TensorProto.FLOAT, [1, len(values)], values)]
    graph = helper.make_graph(nodes, "constant_policy", [observation], [policy], initialisers)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=9)
    onnx.checker.check_model(model)
    return model.SerializeToString()


FRAME = np.full((120, 160), 90, np.uint8)
CONTINUOUS = {"action_space_type": "continuous",
              "action_space": {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 1.0, "high": 3.0}}}


@pytest.mark.parametrize(("means", "steering", "speed"), [
    ([0.0, 0.0], 0.0, 2.0),
    ([1.0, 1.0], 30.0, 3.0),
    ([-1.0, -1.0], -30.0, 1.0),
    ([0.5, -0.5], 15.0, 1.5),
    ([4.0, -9.0], 30.0, 1.0),  # out-of-range means are clipped, as the car does
])
def test_continuous_means_rescale_linearly_to_low_high(means: list[float], steering: float, speed: float) -> None:
    action = OnnxPilot(CONTINUOUS, _constant_policy(means)).act(FRAME)
    assert action["steering_angle"] == pytest.approx(steering, abs=1e-5)
    assert action["speed"] == pytest.approx(speed, abs=1e-5)


def test_discrete_picks_the_most_probable_action_from_the_list() -> None:
    metadata = {"action_space_type": "discrete", "action_space": [
        {"steering_angle": -30, "speed": 0.6}, {"steering_angle": 0, "speed": 1.2}, {"steering_angle": 30,
                                                                                     "speed": 0.8}]}
    pilot = OnnxPilot(metadata, _constant_policy([0.1, 0.2, 0.7]))
    assert pilot.act(FRAME) == {"steering_angle": 30.0, "speed": 0.8}


def test_discrete_model_whose_outputs_do_not_match_the_action_list_is_refused() -> None:
    metadata = {"action_space_type": "discrete", "action_space": [{"steering_angle": 0, "speed": 1.0}] * 5}
    pilot = OnnxPilot(metadata, _constant_policy([0.5, 0.5]))
    with pytest.raises(ArchiveError, match="outputs 2 values but the action space lists 5"):
        pilot.act(FRAME)


def test_continuous_metadata_without_bounds_is_refused() -> None:
    with pytest.raises(ArchiveError, match="speed.low"):
        OnnxPilot({"action_space_type": "continuous", "action_space": {"steering_angle": {"low": -30, "high": 30}}},
                  _constant_policy([0.0, 0.0]))


def test_reused_frame_buffer_gives_what_a_plain_session_run_gives_and_keeps_earlier_outputs() -> None:
    """The pilot feeds onnxruntime through one reused buffer (IOBinding): every frame still gets its own answer,
    and an output already handed out is not overwritten by the next decision."""
    from pathlib import Path

    from drem_sim.env import RaceEnv

    sample = Path(__file__).resolve().parents[2] / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"
    pilot = OnnxPilot.from_archive(sample)
    env = RaceEnv("reinvent_base")
    frame, _ = env.reset(seed=0)
    outputs, frames = [], []
    for _ in range(40):
        frames.append(frame)
        outputs.append(pilot.raw_output(frame))
        frame = env.step({"steering_angle": 25.0, "speed": 1.5})[0]
    for kept, seen in zip(outputs, frames, strict=True):
        plain = pilot.session.run([pilot.output_name], {pilot.input_name: seen.astype(np.float32)[None, ..., None]})
        assert np.array_equal(kept, plain[0].reshape(-1))
    assert len({tuple(o) for o in outputs}) > 10  # the frames really differed, so a stale buffer would show
