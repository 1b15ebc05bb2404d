"""drem's behaviour-cloning network as a frozen TensorFlow 1 graph a stock DeepRacer loads (`agent/model.pb`).

The car's model optimizer feeds the camera to the placeholder named like a Coach clipped-PPO network
(`main_level/agent/main/online/network_0/FRONT_FACING_CAMERA/FRONT_FACING_CAMERA`, NHWC [?,120,160,1], raw pixels)
and reads the PPO head `.../ppo_head_0/policy`; with a continuous action space the car clips those two values to
[-1, 1] and rescales them to the metadata's low..high, which is exactly what our tanh means are made for.

Layout differences from torch are settled here, once: convolution kernels OIHW → HWIO, and the first dense layer's
rows re-ordered because TensorFlow flattens NHWC (h, w, c) while torch flattens NCHW (c, h, w).
`verify_pb` reads the written file back with OpenVINO's TensorFlow frontend and compares with onnxruntime.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from drem_sim.console.graphdef import DT_FLOAT, DT_INT32, Attr, Node, graph_def
from drem_sim.console.heads import input_node, output_node

CAMERA = "FRONT_FACING_CAMERA"
INPUT_NODE = input_node("clipped_ppo", CAMERA)
OUTPUT_NODE = output_node("clipped_ppo")
_PREFIX = "main_level/agent/main/online/network_1/drem_bc"


class PbExportError(RuntimeError):
    """The written graph does not reproduce the ONNX model: it must not ship."""


def _float(value: Any) -> np.ndarray:
    return np.asarray(value.detach().cpu().numpy() if hasattr(value, "detach") else value, dtype=np.float32)


def behaviour_cloning_graph(model: Any) -> bytes:
    """GraphDef bytes of a `BehaviourCloningCNN` (see learn/model.py) in eval mode (dropout is the identity)."""
    import torch

    convolutions = [m for m in model.features if isinstance(m, torch.nn.Conv2d)]
    dense = [m for m in model.head if isinstance(m, torch.nn.Linear)]
    if len(dense) != 2 or not isinstance(model.head[-1], torch.nn.Tanh):
        raise PbExportError("the network is not drem's behaviour-cloning CNN (two dense layers and tanh expected)")
    nodes: list[Node] = []
    float_t = {"T": Attr.type(DT_FLOAT)}

    def const(name: str, value: np.ndarray) -> str:
        dtype = DT_INT32 if value.dtype == np.int32 else DT_FLOAT
        nodes.append(Node(name, "Const", attrs={"dtype": Attr.type(dtype), "value": Attr.tensor(value)}))
        return name

    nodes.append(Node(INPUT_NODE, "Placeholder", attrs={"dtype": Attr.type(DT_FLOAT),
                                                        "shape": Attr.shape([-1, 120, 160, 1])}))
    scale = const(f"{_PREFIX}/rescale/y", np.array(1.0 / 255.0, np.float32))
    nodes.append(Node(f"{_PREFIX}/rescale", "Mul", [INPUT_NODE, scale], dict(float_t)))
    current = f"{_PREFIX}/rescale"
    height, width = 120, 160
    for index, conv in enumerate(convolutions):
        if conv.padding not in ((0, 0), "valid") or conv.dilation != (1, 1) or conv.groups != 1:
            raise PbExportError(f"convolution {index} uses padding, dilation or groups; only valid convolutions")
        stride = conv.stride[0]
        kernel = const(f"{_PREFIX}/conv{index}/kernel", _float(conv.weight).transpose(2, 3, 1, 0).copy())
        bias = const(f"{_PREFIX}/conv{index}/bias", _float(conv.bias))
        name = f"{_PREFIX}/conv{index}"
        nodes.append(Node(f"{name}/Conv2D", "Conv2D", [current, kernel], {
            **float_t, "strides": Attr.ints([1, stride, stride, 1]), "padding": Attr.string("VALID"),
            "data_format": Attr.string("NHWC"), "dilations": Attr.ints([1, 1, 1, 1]),
            "use_cudnn_on_gpu": Attr.boolean(True)}))
        nodes.append(Node(f"{name}/BiasAdd", "BiasAdd", [f"{name}/Conv2D", bias],
                          {**float_t, "data_format": Attr.string("NHWC")}))
        nodes.append(Node(f"{name}/Relu", "Relu", [f"{name}/BiasAdd"], dict(float_t)))
        current = f"{name}/Relu"
        kernel_size = conv.kernel_size[0]
        height, width = (height - kernel_size) // stride + 1, (width - kernel_size) // stride + 1
    channels = convolutions[-1].out_channels
    flat = height * width * channels
    shape = const(f"{_PREFIX}/flatten/shape", np.array([-1, flat], np.int32))
    nodes.append(Node(f"{_PREFIX}/flatten", "Reshape", [current, shape],
                      {**float_t, "Tshape": Attr.type(DT_INT32)}))
    first = _float(dense[0].weight)  # [out, c*h*w] in torch order
    if first.shape[1] != flat:
        raise PbExportError(f"the first dense layer takes {first.shape[1]} inputs, the convolutions give {flat}")
    first = first.reshape(-1, channels, height, width).transpose(2, 3, 1, 0).reshape(flat, -1).copy()
    current = f"{_PREFIX}/flatten"
    for index, (weights, layer) in enumerate(((first, dense[0]), (_float(dense[1].weight).T.copy(), dense[1]))):
        name = f"{_PREFIX}/dense{index}"
        kernel = const(f"{name}/kernel", weights)
        bias = const(f"{name}/bias", _float(layer.bias))
        nodes.append(Node(f"{name}/MatMul", "MatMul", [current, kernel], {
            **float_t, "transpose_a": Attr.boolean(False), "transpose_b": Attr.boolean(False)}))
        nodes.append(Node(f"{name}/BiasAdd", "BiasAdd", [f"{name}/MatMul", bias],
                          {**float_t, "data_format": Attr.string("NHWC")}))
        current = f"{name}/BiasAdd"
        if index == 0:
            nodes.append(Node(f"{name}/Relu", "Relu", [current], dict(float_t)))
            current = f"{name}/Relu"
    nodes.append(Node(OUTPUT_NODE, "Tanh", [current], dict(float_t)))
    return graph_def(nodes)


def write_pb(model: Any, path: Path) -> Path:
    model.eval()
    path.write_bytes(behaviour_cloning_graph(model))
    return path


def verify_pb(pb_path: Path, onnx_path: Path, frames: np.ndarray, tolerance: float = 1e-4) -> float:
    """OpenVINO (the car's runtime) on the .pb against onnxruntime on the ONNX file; the largest difference."""
    import openvino as ov

    from drem_sim.console.convert import onnx_session

    inputs = np.ascontiguousarray(frames, dtype=np.float32).reshape(-1, 120, 160, 1)
    try:
        model = ov.Core().read_model(str(pb_path))
    except Exception as error:  # OpenVINO raises its own types
        raise PbExportError(f"OpenVINO cannot read the written agent/model.pb: {error}") from None
    names = {name.split(":")[0] for port in model.inputs for name in port.get_names()}
    if INPUT_NODE not in names:
        raise PbExportError(f"the graph's input is {sorted(names)}, not {INPUT_NODE}")
    compiled = ov.Core().compile_model(model, "CPU", {"INFERENCE_PRECISION_HINT": "f32",
                                                     "INFERENCE_NUM_THREADS": 1})
    expected = np.stack([compiled(frame[None])[0][0] for frame in inputs])
    session = onnx_session(onnx_path)
    actual = session.run(None, {session.get_inputs()[0].name: inputs})[0]
    difference = float(np.max(np.abs(expected - actual)))
    if not difference <= tolerance:
        raise PbExportError(f"agent/model.pb differs from model.onnx by {difference:.2e} (> {tolerance:.0e})")
    return difference
