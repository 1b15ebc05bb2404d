"""Torch → ONNX export, checked against onnxruntime before anything ships."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import onnx
import torch
from torch import nn

from drem_sim.learn.contract import IMAGE_HEIGHT, IMAGE_WIDTH, INPUT_NAME, OUTPUT_NAME, onnx_session  # noqa: F401

OPSET = 17
# Pinned, not left to the exporter: the onnxruntime on cars and here reads IR <= 13 only, while newer onnx/torch
# releases stamp the newest IR they know. IR 8 is all opset 17 needs.
IR_VERSION = 8
TOLERANCE = 1e-4


class ExportMismatchError(RuntimeError):
    """onnxruntime disagrees with torch: the exported graph is not the trained model."""


def export_onnx(model: nn.Module, path: Path) -> Path:
    model.eval()
    example = torch.zeros(1, IMAGE_HEIGHT, IMAGE_WIDTH, 1)
    # The dynamo exporter needs onnxscript, which we do not ship; the TorchScript path does this graph fine.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # "legacy exporter": chosen on purpose, see above
        torch.onnx.export(model, (example,), str(path), input_names=[INPUT_NAME], output_names=[OUTPUT_NAME],
                          dynamic_axes={INPUT_NAME: {0: "batch"}, OUTPUT_NAME: {0: "batch"}},
                          opset_version=OPSET, dynamo=False)
    graph = onnx.load(str(path))
    graph.ir_version = IR_VERSION
    onnx.checker.check_model(graph)
    onnx.save(graph, str(path))
    return path


def verify_onnx(model: nn.Module, path: Path, samples: np.ndarray, tolerance: float = TOLERANCE) -> float:
    """Run the same uint8 frames through torch and onnxruntime; return the largest difference."""
    inputs = np.ascontiguousarray(samples, dtype=np.float32).reshape(-1, IMAGE_HEIGHT, IMAGE_WIDTH, 1)
    model.eval()
    with torch.no_grad():
        expected = model(torch.from_numpy(inputs)).numpy()
    actual = onnx_session(path).run([OUTPUT_NAME], {INPUT_NAME: inputs})[0]
    difference = float(np.max(np.abs(expected - actual)))
    if difference > tolerance:
        raise ExportMismatchError(f"onnxruntime output differs from torch by {difference:.2e} (> {tolerance:.0e})")
    return difference
