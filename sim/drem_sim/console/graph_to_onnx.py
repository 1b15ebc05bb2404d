"""Translate an OpenVINO model (as OpenVINO's TensorFlow frontend reads a frozen `.pb`) into an ONNX graph.

OpenVINO reads TensorFlow 1 frozen graphs without TensorFlow, but writes only its own IR; ONNX is what our
simulator and car agent run (onnxruntime). So this module walks OpenVINO's operations in topological order and
writes each one as the ONNX operator(s) with the same semantics, using the `onnx` package's helpers.

Only the operations DeepRacer networks are made of are known (convolutions, dense layers, activations, softmax,
the flatten's shape arithmetic, batch norm). Anything else raises `UnsupportedGraph` naming the operation: such a
model still races on a stock car, it just cannot be scrutineered here. Every translation is checked afterwards by
running the same frames through OpenVINO and onnxruntime (`convert.py`), so a subtle mistake here cannot pass.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OPSET = 17
# The onnxruntime we ship reads IR <= 13 only (same pin as learn/export.py); IR 8 is all opset 17 needs.
IR_VERSION = 8

_ELEMENT_TYPES = {"f32": TensorProto.FLOAT, "f16": TensorProto.FLOAT16, "f64": TensorProto.DOUBLE,
                  "i32": TensorProto.INT32, "i64": TensorProto.INT64, "u8": TensorProto.UINT8,
                  "boolean": TensorProto.BOOL}
_BINARY = {"Add": "Add", "Subtract": "Sub", "Multiply": "Mul", "Divide": "Div", "Maximum": "Max",
           "Minimum": "Min", "Power": "Pow"}
_UNARY = {"Relu": "Relu", "Tanh": "Tanh", "Sigmoid": "Sigmoid", "Exp": "Exp", "Log": "Log", "Sqrt": "Sqrt",
          "Negative": "Neg", "Abs": "Abs", "Floor": "Floor"}


class UnsupportedGraph(ValueError):
    """The graph uses something this translator does not know; the message names it."""


def _element_type(ov_type: Any) -> int:
    name = ov_type.get_type_name()
    if name not in _ELEMENT_TYPES:
        raise UnsupportedGraph(f"tensor element type {name} is not supported")
    return _ELEMENT_TYPES[name]


class _Writer:
    def __init__(self) -> None:
        self.nodes: list[onnx.NodeProto] = []
        self.initializers: list[onnx.TensorProto] = []
        self._emitted: set[str] = set()
        self._counter = 0

    def fresh(self, hint: str) -> str:
        self._counter += 1
        return f"{hint}__{self._counter}"

    def constant(self, name: str, value: np.ndarray) -> str:
        if name not in self._emitted:
            self._emitted.add(name)
            self.initializers.append(numpy_helper.from_array(np.ascontiguousarray(value), name))
        return name

    def node(self, op_type: str, inputs: list[str], outputs: list[str] | None = None, **attributes: Any) -> str:
        outputs = outputs or [self.fresh(op_type)]
        self.nodes.append(helper.make_node(op_type, inputs, outputs, **attributes))
        return outputs[0]


class _Translator:
    def __init__(self, model: Any, input_name: str, output_name: str) -> None:
        self.model = model
        self.input_name = input_name
        self.output_name = output_name
        self.writer = _Writer()
        self.graph_inputs: list[onnx.ValueInfoProto] = []
        self.graph_outputs: list[onnx.ValueInfoProto] = []
        self._handlers: dict[str, Callable[[Any], None]] = {
            "Parameter": self._parameter, "Constant": lambda op: None, "Result": self._result,
            "Convolution": self._convolution, "MatMul": self._matmul, "Softmax": self._softmax,
            "Transpose": self._transpose, "Reshape": self._reshape, "ShapeOf": self._shape_of,
            "Gather": self._gather, "StridedSlice": self._strided_slice, "Unsqueeze": self._unsqueeze,
            "Squeeze": self._squeeze, "Concat": self._concat, "Convert": self._convert, "Clamp": self._clamp,
            "BatchNormInference": self._batch_norm,
        }

    # -- plumbing ------------------------------------------------------------------------------------------------

    def name_of(self, output: Any) -> str:
        """The ONNX tensor name of an OpenVINO output port; constants become initializers on first use."""
        node = output.get_node()
        name = f"{node.get_name()}:{output.get_index()}"
        if node.get_type_name() == "Constant":
            return self.writer.constant(name, self.constant_value(output))
        if node.get_type_name() == "Parameter":
            return self.input_name
        return name

    @staticmethod
    def constant_value(output: Any) -> np.ndarray:
        node = output.get_node()
        value = np.array(node.get_data(), copy=True)
        return value.reshape(tuple(node.get_output_shape(0)))

    def input_name_of(self, op: Any, index: int) -> str:
        return self.name_of(op.input(index).get_source_output())

    def constant_input(self, op: Any, index: int, what: str) -> np.ndarray:
        source = op.input(index).get_source_output()
        if source.get_node().get_type_name() != "Constant":
            raise UnsupportedGraph(f"{op.get_type_name()} {op.get_friendly_name()!r}: a computed {what} is not "
                                   "supported")
        return self.constant_value(source)

    def outputs_of(self, op: Any) -> list[str]:
        return [f"{op.get_name()}:{index}" for index in range(op.get_output_size())]

    def rank_of(self, op: Any, index: int) -> int:
        shape = op.input(index).get_partial_shape()
        if shape.rank.is_dynamic:
            raise UnsupportedGraph(f"{op.get_type_name()} {op.get_friendly_name()!r} has an input of unknown rank")
        return shape.rank.get_length()

    def int64_input(self, op: Any, index: int) -> str:
        source = op.input(index).get_source_output()
        if source.get_node().get_type_name() == "Constant":
            value = self.constant_value(source).astype(np.int64)
            return self.writer.constant(f"{source.get_node().get_name()}:{source.get_index()}:i64", value)
        return self.writer.node("Cast", [self.name_of(source)], to=TensorProto.INT64)

    def numpy_broadcast(self, op: Any) -> None:
        attributes = op.get_attributes()
        broadcast = str(attributes.get("auto_broadcast", "numpy")).lower()
        if broadcast not in ("numpy", "none"):
            raise UnsupportedGraph(f"{op.get_type_name()} with {broadcast} broadcasting is not supported")

    # -- translation ---------------------------------------------------------------------------------------------

    def run(self) -> onnx.ModelProto:
        for op in self.model.get_ordered_ops():
            kind = op.get_type_name()
            if kind in _BINARY:
                self.numpy_broadcast(op)
                self.writer.node(_BINARY[kind], [self.input_name_of(op, 0), self.input_name_of(op, 1)],
                                 self.outputs_of(op))
            elif kind in _UNARY:
                self.writer.node(_UNARY[kind], [self.input_name_of(op, 0)], self.outputs_of(op))
            elif kind in self._handlers:
                self._handlers[kind](op)
            else:
                raise UnsupportedGraph(f"operation {kind} ({op.get_friendly_name()}) is not supported")
        if not self.graph_inputs or not self.graph_outputs:
            raise UnsupportedGraph("the graph has no camera input or no policy output")
        graph = helper.make_graph(self.writer.nodes, "deepracer_policy", self.graph_inputs, self.graph_outputs,
                                  self.writer.initializers)
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                                  producer_name="drem console-model converter")
        model.ir_version = IR_VERSION
        return model

    def _parameter(self, op: Any) -> None:
        if self.graph_inputs:
            raise UnsupportedGraph("the graph has more than one input (stereo or lidar networks are not supported)")
        shape = [dim.get_length() if dim.is_static else "batch" for dim in op.get_output_partial_shape(0)]
        self.graph_inputs.append(helper.make_tensor_value_info(
            self.input_name, _element_type(op.get_output_element_type(0)), shape))

    def _result(self, op: Any) -> None:
        source = self.input_name_of(op, 0)
        self.writer.node("Identity", [source], [self.output_name])
        shape = [dim.get_length() if dim.is_static else "batch" for dim in op.get_output_partial_shape(0)]
        self.graph_outputs.append(helper.make_tensor_value_info(
            self.output_name, _element_type(op.get_output_element_type(0)), shape))

    def _convolution(self, op: Any) -> None:
        attributes = op.get_attributes()
        kernel = self.constant_input(op, 1, "convolution kernel")
        spatial = kernel.ndim - 2
        extra: dict[str, Any] = {}
        auto_pad = str(attributes.get("auto_pad", "explicit")).lower()
        if auto_pad == "valid":
            extra["pads"] = [0] * (2 * spatial)
        elif auto_pad == "same_upper":
            extra["auto_pad"] = "SAME_UPPER"
        elif auto_pad == "same_lower":
            extra["auto_pad"] = "SAME_LOWER"
        else:
            extra["pads"] = list(attributes["pads_begin"]) + list(attributes["pads_end"])
        self.writer.node("Conv", [self.input_name_of(op, 0), self.input_name_of(op, 1)], self.outputs_of(op),
                         strides=list(attributes["strides"]), dilations=list(attributes["dilations"]),
                         kernel_shape=list(kernel.shape[2:]), **extra)

    def _matmul(self, op: Any) -> None:
        attributes = op.get_attributes()
        operands = []
        for index, flag in ((0, attributes.get("transpose_a", False)), (1, attributes.get("transpose_b", False))):
            name = self.input_name_of(op, index)
            if flag:
                rank = self.rank_of(op, index)
                perm = list(range(rank - 2)) + [rank - 1, rank - 2]
                name = self.writer.node("Transpose", [name], perm=perm)
            operands.append(name)
        self.writer.node("MatMul", operands, self.outputs_of(op))

    def _softmax(self, op: Any) -> None:
        self.writer.node("Softmax", [self.input_name_of(op, 0)], self.outputs_of(op),
                         axis=int(op.get_attributes().get("axis", 1)))

    def _transpose(self, op: Any) -> None:
        perm = self.constant_input(op, 1, "transpose order").astype(np.int64).reshape(-1).tolist()
        self.writer.node("Transpose", [self.input_name_of(op, 0)], self.outputs_of(op), perm=perm)

    def _reshape(self, op: Any) -> None:
        special_zero = bool(op.get_attributes().get("special_zero", False))
        source = op.input(1).get_source_output()
        literal_zero = (not special_zero and source.get_node().get_type_name() == "Constant"
                        and bool(np.any(self.constant_value(source) == 0)))
        # OpenVINO's special_zero=False means a 0 is a zero-sized dimension; ONNX needs allowzero=1 for that.
        self.writer.node("Reshape", [self.input_name_of(op, 0), self.int64_input(op, 1)], self.outputs_of(op),
                         **({"allowzero": 1} if literal_zero else {}))

    def _shape_of(self, op: Any) -> None:
        shape = self.writer.node("Shape", [self.input_name_of(op, 0)])
        self.writer.node("Cast", [shape], self.outputs_of(op), to=_element_type(op.get_output_element_type(0)))

    def _gather(self, op: Any) -> None:
        if int(op.get_attributes().get("batch_dims", 0)) != 0:
            raise UnsupportedGraph(f"Gather {op.get_friendly_name()!r} with batch_dims is not supported")
        axis = int(self.constant_input(op, 2, "gather axis").reshape(-1)[0])
        self.writer.node("Gather", [self.input_name_of(op, 0), self.input_name_of(op, 1)], self.outputs_of(op),
                         axis=axis)

    def _strided_slice(self, op: Any) -> None:
        attributes = op.get_attributes()
        if any(attributes.get("new_axis_mask", [])) or any(attributes.get("ellipsis_mask", [])):
            raise UnsupportedGraph(f"StridedSlice {op.get_friendly_name()!r} with new-axis or ellipsis masks")
        begin = self.constant_input(op, 1, "slice begin").astype(np.int64).reshape(-1)
        end = self.constant_input(op, 2, "slice end").astype(np.int64).reshape(-1)
        strides = (self.constant_input(op, 3, "slice stride").astype(np.int64).reshape(-1)
                   if op.get_input_size() > 3 else np.ones_like(begin))
        if np.any(strides <= 0):
            raise UnsupportedGraph(f"StridedSlice {op.get_friendly_name()!r} with a negative stride")
        begin_mask, end_mask = _mask(attributes, "begin_mask", len(begin)), _mask(attributes, "end_mask", len(begin))
        shrink = _mask(attributes, "shrink_axis_mask", len(begin))
        largest = np.iinfo(np.int64).max
        starts, ends = [], []
        for axis in range(len(begin)):
            start = 0 if begin_mask[axis] else int(begin[axis])
            stop = largest if end_mask[axis] else int(end[axis])
            if shrink[axis]:
                start = int(begin[axis])
                stop = largest if start == -1 else start + 1
            starts.append(start)
            ends.append(stop)
        name = op.get_name()
        sliced = self.writer.node("Slice", [
            self.input_name_of(op, 0),
            self.writer.constant(f"{name}:starts", np.array(starts, np.int64)),
            self.writer.constant(f"{name}:ends", np.array(ends, np.int64)),
            self.writer.constant(f"{name}:axes", np.arange(len(begin), dtype=np.int64)),
            self.writer.constant(f"{name}:steps", strides.astype(np.int64)),
        ], None if any(shrink) else self.outputs_of(op))
        if any(shrink):
            axes = np.array([axis for axis in range(len(begin)) if shrink[axis]], np.int64)
            self.writer.node("Squeeze", [sliced, self.writer.constant(f"{name}:squeeze", axes)], self.outputs_of(op))

    def _unsqueeze(self, op: Any) -> None:
        self.writer.node("Unsqueeze", [self.input_name_of(op, 0), self.int64_input(op, 1)], self.outputs_of(op))

    def _squeeze(self, op: Any) -> None:
        inputs = [self.input_name_of(op, 0)] + ([self.int64_input(op, 1)] if op.get_input_size() > 1 else [])
        self.writer.node("Squeeze", inputs, self.outputs_of(op))

    def _concat(self, op: Any) -> None:
        inputs = [self.input_name_of(op, index) for index in range(op.get_input_size())]
        self.writer.node("Concat", inputs, self.outputs_of(op), axis=int(op.get_attributes()["axis"]))

    def _convert(self, op: Any) -> None:
        self.writer.node("Cast", [self.input_name_of(op, 0)], self.outputs_of(op),
                         to=_element_type(op.get_output_element_type(0)))

    def _clamp(self, op: Any) -> None:
        attributes = op.get_attributes()
        name = op.get_name()
        bounds = [self.writer.constant(f"{name}:{key}", np.array(attributes[key], np.float32)) for key in ("min",
                                                                                                           "max")]
        self.writer.node("Clip", [self.input_name_of(op, 0), *bounds], self.outputs_of(op))

    def _batch_norm(self, op: Any) -> None:
        # OpenVINO v5 order: data, gamma, beta, mean, variance; ONNX: X, scale, B, mean, var.
        inputs = [self.input_name_of(op, index) for index in range(5)]
        self.writer.node("BatchNormalization", inputs, self.outputs_of(op),
                         epsilon=float(op.get_attributes()["epsilon"]))


def _mask(attributes: dict[str, Any], key: str, length: int) -> list[int]:
    values = [int(v) for v in attributes.get(key, [])]
    return (values + [0] * length)[:length]


def openvino_to_onnx(model: Any, input_name: str, output_name: str) -> onnx.ModelProto:
    """The ONNX translation of an OpenVINO model with one image input and one output."""
    if len(model.outputs) != 1:
        raise UnsupportedGraph(f"the graph has {len(model.outputs)} outputs; a DeepRacer policy has one")
    translated = _Translator(model, input_name, output_name).run()
    onnx.checker.check_model(translated)
    return translated
