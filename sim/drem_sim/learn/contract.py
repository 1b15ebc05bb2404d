"""The tensor contract of drem's models and the onnxruntime session that runs them, without torch.

Evaluating, packaging and driving a model need only these (onnxruntime is in the `sim` and `car` extras); torch is
the optional `train` extra, so `drem sim eval` must not import it (issue 13: `make up` installs no torch).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

IMAGE_HEIGHT = 120
IMAGE_WIDTH = 160
INPUT_NAME = "observation"
OUTPUT_NAME = "policy"
NETWORK_NAME = "DREM_BC_CNN_SMALL"


def onnx_session(model_bytes_or_path: bytes | Path) -> Any:
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    source = model_bytes_or_path if isinstance(model_bytes_or_path, bytes) else str(model_bytes_or_path)
    return onnxruntime.InferenceSession(source, options, providers=["CPUExecutionProvider"])
