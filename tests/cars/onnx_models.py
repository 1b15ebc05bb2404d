"""Tiny real ONNX policies with DeepRacer's input contract, built with onnx.helper, and model folders for them."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper


def mean_brightness_policy(weights: list[float], biases: list[float]) -> bytes:
    """[1,120,160,1] → mean pixel (0..255) → outputs_i = weights_i · mean + biases_i. Output depends on the frame."""
    image = helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 120, 160, 1])
    out = helper.make_tensor_value_info("policy", TensorProto.FLOAT, [1, len(weights)])
    graph = helper.make_graph(
        [helper.make_node("ReduceMean", ["image"], ["mean"], axes=[1, 2, 3], keepdims=0),
         helper.make_node("Mul", ["mean", "w"], ["scaled"]),
         helper.make_node("Add", ["scaled", "b"], ["policy"])],
        "policy", [image], [out],
        initializer=[helper.make_tensor("w", TensorProto.FLOAT, [1, len(weights)], weights),
                     helper.make_tensor("b", TensorProto.FLOAT, [1, len(biases)], biases)])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8  # what the installed onnxruntime reads
    onnx.checker.check_model(model)
    return model.SerializeToString()


DISCRETE_ACTIONS = [{"steering_angle": -30, "speed": 0.6}, {"steering_angle": 0, "speed": 1.2},
                    {"steering_angle": 30, "speed": 0.6}]
CONTINUOUS_SPACE = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2.0}}


def model_dir(root: Path, onnx_bytes: bytes, metadata: dict) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "model.onnx").write_bytes(onnx_bytes)
    (root / "model_metadata.json").write_text(json.dumps(metadata))
    return root


def frame(value: int) -> np.ndarray:
    return np.full((120, 160), value, dtype=np.uint8)
