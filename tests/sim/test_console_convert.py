"""Console graphs (TensorFlow 1 frozen .pb) to ONNX: read by OpenVINO, written with onnx, run by onnxruntime."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import openvino as ov
import pytest
from openvino import opset13 as ops

from drem_sim.console.convert import TOLERANCE, convert, onnx_session
from drem_sim.console.graph_to_onnx import IR_VERSION, UnsupportedGraph, openvino_to_onnx
from tests import console_fixture

pytestmark = pytest.mark.sim


def _unpack(tmp_path: Path, metadata: dict | None = None) -> tuple[Path, dict]:
    files = console_fixture.members()
    pb = tmp_path / "model.pb"
    pb.write_bytes(files["agent/model.pb"])
    document = {**json.loads(files["model_metadata.json"]), **(metadata or {})}
    return pb, document


def test_the_console_fixture_converts_and_reproduces_the_graphs_own_outputs(tmp_path: Path) -> None:
    pb, metadata = _unpack(tmp_path)
    out = tmp_path / "model.onnx"

    result = convert(pb, metadata, out)

    assert result.outcome == "converted", result.reason
    assert result.max_abs_diff is not None and result.max_abs_diff <= TOLERANCE
    session = onnx_session(out)
    assert session.get_inputs()[0].name == ("main_level/agent/main/online/network_0/FRONT_FACING_CAMERA/"
                                            "FRONT_FACING_CAMERA")
    frames = np.load(console_fixture.FRAMES).astype(np.float32)  # raw 0..255: the graph divides by 255 itself
    expected = np.load(console_fixture.EXPECTED)
    actual = session.run(None, {session.get_inputs()[0].name: frames})[0]
    assert actual.shape == (5, 9)
    # Every row, the fifth included, is the graph's own output for the uint8 frame (../shared/deepracer-models/
    # SOURCE.md): a correct conversion reproduces them all to ~1e-5.
    assert np.max(np.abs(actual - expected)) <= 1e-5
    assert list(actual.argmax(axis=1)) == list(expected.argmax(axis=1))
    # and OpenVINO on the original .pb agrees on the fixture frames too (the car's own runtime)
    compiled = ov.Core().compile_model(ov.Core().read_model(str(pb)), "CPU", {"INFERENCE_PRECISION_HINT": "f32"})
    assert np.max(np.abs(compiled(frames)[0] - actual)) <= TOLERANCE
    import onnx
    assert onnx.load(str(out)).ir_version == IR_VERSION  # an IR our onnxruntime (<= 13) reads


def test_stereo_or_lidar_models_cannot_be_scrutineered_and_say_why(tmp_path: Path) -> None:
    pb, metadata = _unpack(tmp_path, {"sensor": ["STEREO_CAMERAS", "LIDAR"]})
    result = convert(pb, metadata, tmp_path / "out.onnx")
    assert result.outcome == "cannot_scrutineer"
    assert "STEREO_CAMERAS" in (result.reason or "") and "one front camera" in (result.reason or "")
    assert not (tmp_path / "out.onnx").exists()


def test_a_file_that_is_not_a_graph_is_not_raceable_and_says_why(tmp_path: Path) -> None:
    pb = tmp_path / "model.pb"
    pb.write_bytes(b"\x0a\xff\xff\xff\xff\x0f this is not a GraphDef")
    result = convert(pb, {"sensor": ["FRONT_FACING_CAMERA"]}, tmp_path / "out.onnx")
    assert result.outcome == "not_raceable"
    assert (result.reason or "").startswith("a stock car cannot load this model: its agent/model.pb is damaged")
    assert (result.detail or "").startswith("OpenVINO cannot read agent/model.pb")


def test_a_truncated_console_graph_is_not_raceable_with_openvinos_meaningful_words_for_staff(tmp_path: Path) -> None:
    pb, metadata = _unpack(tmp_path)
    whole = pb.read_bytes()
    pb.write_bytes(whole[: len(whole) // 2])  # a download cut short
    result = convert(pb, metadata, tmp_path / "out.onnx")
    assert result.outcome == "not_raceable" and not (tmp_path / "out.onnx").exists()
    assert "damaged or incomplete" in (result.reason or "")
    detail = result.detail or ""
    assert "Unable to read the model" in detail, detail  # OpenVINO's reason, not its source location
    assert "Exception from" not in detail and ".cpp" not in detail and str(tmp_path) not in detail, detail


def test_metadata_whose_actions_disagree_with_the_network_is_not_raceable(tmp_path: Path) -> None:
    pb, metadata = _unpack(tmp_path)
    two = {"action_space": metadata["action_space"][:2]}  # the fixture's network chooses among 9
    result = convert(pb, {**metadata, **two}, tmp_path / "out.onnx")
    assert result.outcome == "not_raceable" and not (tmp_path / "out.onnx").exists()
    assert "would drive this model wrongly" in (result.reason or "")
    assert "2 actions in model_metadata.json but its network chooses among 9" in (result.reason or "")
    continuous = {"action_space_type": "continuous",
                  "action_space": {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 1}}}
    result = convert(pb, {**metadata, **continuous}, tmp_path / "out.onnx")
    assert result.outcome == "not_raceable" and "network outputs 9" in (result.reason or "")


def _camera() -> ov.Node:
    return ops.parameter(ov.PartialShape([-1, 120, 160, 1]), ov.Type.f32, name="camera")


def test_an_operation_the_translator_does_not_know_is_named() -> None:
    camera = _camera()
    model = ov.Model([ops.sin(camera)], [camera], "odd")
    with pytest.raises(UnsupportedGraph, match="operation Sin"):
        openvino_to_onnx(model, "camera", "policy")


def test_a_continuous_head_with_tanh_and_transposed_dense_translates_exactly() -> None:
    rng = np.random.default_rng(3)
    camera = _camera()
    scaled = ops.multiply(camera, ops.constant(np.float32(1 / 255)))
    nchw = ops.transpose(scaled, ops.constant(np.array([0, 3, 1, 2], np.int64)))
    conv = ops.convolution(nchw, ops.constant(rng.normal(0, 0.1, (8, 1, 5, 5)).astype(np.float32)),
                           [3, 3], [1, 1], [2, 2], [1, 1], auto_pad="explicit")
    relu = ops.relu(ops.add(conv, ops.constant(rng.normal(0, 0.1, (1, 8, 1, 1)).astype(np.float32))))
    flat = ops.reshape(relu, ops.constant(np.array([-1, 8 * 40 * 53], np.int64)), special_zero=False)
    dense = ops.matmul(flat, ops.constant(rng.normal(0, 0.01, (2, 8 * 40 * 53)).astype(np.float32)), False, True)
    model = ov.Model([ops.tanh(dense)], [camera], "continuous")

    translated = openvino_to_onnx(model, "camera", "policy")

    frames = rng.integers(0, 256, (3, 120, 160, 1)).astype(np.float32)
    expected = ov.Core().compile_model(model, "CPU", {"INFERENCE_PRECISION_HINT": "f32"})(frames)[0]
    actual = onnx_session(translated.SerializeToString()).run(None, {"camera": frames})[0]
    assert actual.shape == (3, 2)
    assert np.max(np.abs(actual - expected)) <= TOLERANCE


def _tiny_pb(path: Path, *, network: str, head: str, extra_op: str | None = None, second_head: str | None = None,
             outputs: int = 2) -> Path:
    """A small frozen graph with Coach's names, written with drem's own GraphDef encoder (no TensorFlow)."""
    from drem_sim.console.graphdef import DT_FLOAT, DT_INT32, Attr, Node, graph_def

    rng = np.random.default_rng(5)
    camera = f"main_level/agent/{network}/online/network_0/FRONT_FACING_CAMERA/FRONT_FACING_CAMERA"
    t = {"T": Attr.type(DT_FLOAT)}
    nodes = [Node(camera, "Placeholder", attrs={"dtype": Attr.type(DT_FLOAT), "shape": Attr.shape([-1, 120, 160, 1])}),
             Node("scale", "Const", attrs={"dtype": Attr.type(DT_FLOAT), "value": Attr.tensor(np.array(1 / 255,
                                                                                                       np.float32))}),
             Node("scaled", "Mul", [camera, "scale"], dict(t)),
             Node("shape", "Const", attrs={"dtype": Attr.type(DT_INT32), "value": Attr.tensor(np.array([-1, 19200],
                                                                                                       np.int32))}),
             Node("flat", "Reshape", ["scaled", "shape"], {**t, "Tshape": Attr.type(DT_INT32)})]
    last = "flat"
    if extra_op:
        nodes.append(Node("odd", extra_op, ["flat"], dict(t)))
        last = "odd"
    for name, size in ((head, outputs), (second_head, 1)):
        if name is None:
            continue
        weights = rng.normal(0, 0.02, (19200, size)).astype(np.float32)
        nodes += [Node(f"{name}/w", "Const", attrs={"dtype": Attr.type(DT_FLOAT), "value": Attr.tensor(weights)}),
                  Node(f"{name}/MatMul", "MatMul", [last, f"{name}/w"], {**t, "transpose_a": Attr.boolean(False),
                                                                           "transpose_b": Attr.boolean(False)}),
                  Node(name, "Identity", [f"{name}/MatMul"], dict(t))]
    path.write_bytes(graph_def(nodes))
    return path


def test_sac_graphs_use_the_policy_network_names_and_the_policy_head(tmp_path: Path) -> None:
    from drem_sim.console.heads import input_node, output_node

    pb = _tiny_pb(tmp_path / "sac.pb", network="policy", head=output_node("sac"),
                  second_head="main_level/agent/policy/online/network_0/sac_q_head_0/q")
    metadata = {"sensor": ["FRONT_FACING_CAMERA"], "training_algorithm": "sac"}

    result = convert(pb, metadata, tmp_path / "sac.onnx")

    assert result.outcome == "converted", result.reason
    session = onnx_session(tmp_path / "sac.onnx")
    assert session.get_inputs()[0].name == input_node("sac", "FRONT_FACING_CAMERA")
    assert [o.name for o in session.get_outputs()] == [output_node("sac")]  # the q head is left out
    assert session.get_outputs()[0].shape[-1] == 2


def test_an_operation_openvino_reads_but_drem_cannot_translate_is_named(tmp_path: Path) -> None:
    pb = _tiny_pb(tmp_path / "odd.pb", network="main", head="main_level/agent/main/online/network_1/ppo_head_0/policy",
                  extra_op="Sin")
    result = convert(pb, {"sensor": ["FRONT_FACING_CAMERA"]}, tmp_path / "odd.onnx")
    assert result.outcome == "cannot_scrutineer"
    assert "operation Sin" in (result.reason or "") and "not supported" in (result.reason or "")
