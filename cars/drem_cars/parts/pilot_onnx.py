"""The autopilot part: a camera frame in, DeepRacer's action out, following the model's `model_metadata.json`.

Input contract (as on a DeepRacer): grayscale 160x120, NHWC float32 [1, 120, 160, 1], raw 0..255 (the graph does
any scaling). Discrete action spaces take the argmax over the action list; continuous ones clip the two means to
[-1, 1] and rescale linearly to low..high. A single intra-op thread keeps inference from fighting the drive loop.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from drem_cars.model_files import ActionSpace, ModelError, action_space_of, onnx_file, read_metadata

IMAGE_HEIGHT, IMAGE_WIDTH = 120, 160


class OnnxPilot:
    def __init__(self, model_dir: Path | str) -> None:
        import onnxruntime  # loaded only when a car actually drives

        self.model_dir = Path(model_dir)
        self.metadata = read_metadata(self.model_dir)
        self.action_space: ActionSpace = action_space_of(self.metadata)
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = 1
        options.inter_op_num_threads = 1
        try:
            self.session = onnxruntime.InferenceSession(str(onnx_file(self.model_dir)), options,
                                                        providers=["CPUExecutionProvider"])
        except ModelError:
            raise
        except Exception as exc:  # onnxruntime raises its own exception types for a broken graph
            raise ModelError(f"{self.model_dir.name}: onnxruntime cannot load model.onnx ({exc})") from None
        self.input_name = self.session.get_inputs()[0].name
        self.output_name = self.session.get_outputs()[0].name
        self.last_inference_ms = 0.0

    @property
    def name(self) -> str:
        return self.model_dir.name

    def run(self, image: np.ndarray | None) -> tuple[float | None, float | None, float | None]:
        """(steering_deg, speed, inference_ms); all None without a frame."""
        if image is None:
            return None, None, None
        frame = preprocess(image)
        started = time.perf_counter()
        output = self.session.run([self.output_name], {self.input_name: frame})[0]
        self.last_inference_ms = (time.perf_counter() - started) * 1000
        steering, speed = self.action_from_output(output)
        return steering, speed, self.last_inference_ms

    def action_from_output(self, output: np.ndarray) -> tuple[float, float]:
        values = np.asarray(output, dtype=np.float64).reshape(-1)
        space = self.action_space
        if space.kind == "continuous":
            if values.shape[0] < 2:
                raise ModelError(f"a continuous model must output 2 means, this one outputs {values.shape[0]}")
            steering, speed = np.clip(values[:2], -1.0, 1.0)
            return _rescale(float(steering), space.steering), _rescale(float(speed), space.speed)
        if values.shape[0] != len(space.actions):
            raise ModelError(f"the model outputs {values.shape[0]} values but the action space lists "
                             f"{len(space.actions)} actions")
        return space.actions[int(np.argmax(values))]


def preprocess(image: np.ndarray) -> np.ndarray:
    """Any camera frame → grayscale 120x160 → float32 NHWC [1, 120, 160, 1], values kept in 0..255."""
    frame = np.asarray(image)
    if frame.ndim == 3 and frame.shape[2] == 1:
        frame = frame[:, :, 0]
    if frame.ndim == 3 or frame.shape != (IMAGE_HEIGHT, IMAGE_WIDTH):
        import cv2

        if frame.ndim == 3:
            frame = cv2.cvtColor(frame.astype(np.uint8), cv2.COLOR_BGR2GRAY)
        frame = cv2.resize(frame, (IMAGE_WIDTH, IMAGE_HEIGHT), interpolation=cv2.INTER_AREA)
    return frame.astype(np.float32).reshape(1, IMAGE_HEIGHT, IMAGE_WIDTH, 1)


def _rescale(unit: float, bounds: tuple[float, float]) -> float:
    low, high = bounds
    return low + (unit + 1.0) * 0.5 * (high - low)
