"""OnnxPilot: turns camera frames into actions by following a model archive's metadata."""
from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np

from drem_sim.learn.package import ONNX_MEMBER, TENSORFLOW_MEMBER, ArchiveError, load_metadata, read_model_files


class TensorFlowModelError(ArchiveError):
    """The archive holds a console (TensorFlow) model, which the simulator cannot run."""


class NotRaceableModel(ArchiveError):
    """A console model no stock car could load or would drive as its metadata says: `reason` in a racer's words,
    `detail` what OpenVINO said (for staff)."""

    def __init__(self, reason: str, detail: str | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.detail = detail


class OnnxPilot:
    """Continuous action spaces rescale the [-1, 1] means to low..high; discrete ones take the argmax action."""

    def __init__(self, metadata: dict[str, Any], onnx_model: bytes) -> None:
        from drem_sim.learn.contract import onnx_session  # onnxruntime loads only when a pilot is built

        self.metadata = metadata
        self.kind = str(metadata.get("action_space_type", "discrete"))
        self.action_space = metadata["action_space"]
        self._check_action_space()
        self.session = onnx_session(onnx_model)
        tensors = metadata.get("drem", {})
        self.input_name = tensors.get("input", {}).get("name") or self.session.get_inputs()[0].name
        self.output_name = tensors.get("output", {}).get("name") or self.session.get_outputs()[0].name
        # One float32 frame buffer and one IOBinding, reused for every decision (the simulator's hot path): the
        # session reads the same bytes `session.run` would get, without a new input array and feed dict per call.
        self._frame: np.ndarray | None = None
        self._binding: Any = None
        self._lock = threading.Lock()  # the buffer is shared: one decision at a time per pilot

    @classmethod
    def from_archive(cls, source: Path | str) -> OnnxPilot:
        """An ONNX archive drives as is; a console archive (agent/model.pb) is converted to ONNX first."""
        files = read_model_files(Path(source))
        metadata = load_metadata(files)
        if ONNX_MEMBER not in files:
            if TENSORFLOW_MEMBER in files:
                return cls(metadata, _converted(files[TENSORFLOW_MEMBER], metadata))
            raise ArchiveError(f"the archive has no {ONNX_MEMBER}")
        return cls(metadata, files[ONNX_MEMBER])

    def _check_action_space(self) -> None:
        if self.kind == "continuous":
            for key in ("steering_angle", "speed"):
                bounds = self.action_space.get(key) if isinstance(self.action_space, dict) else None
                if not bounds or "low" not in bounds or "high" not in bounds:
                    raise ArchiveError(f"continuous action_space needs {key}.low and {key}.high")
        elif self.kind == "discrete":
            if not isinstance(self.action_space, list) or not self.action_space:
                raise ArchiveError("discrete action_space must be a non-empty list of actions")
        else:
            raise ArchiveError(f"unknown action_space_type {self.kind!r}")

    def raw_output(self, observation: np.ndarray) -> np.ndarray:
        height, width = observation.shape[0], observation.shape[1]
        if observation.size != height * width:  # not one grey frame: the plain path reports what is wrong
            return self._run_plain(observation)
        with self._lock:
            try:
                binding = self._bound(height, width)
                np.copyto(self._frame.reshape(height, width), observation.reshape(height, width),  # type: ignore[union-attr]
                          casting="unsafe")
                self.session.run_with_iobinding(binding)
                output = binding.copy_outputs_to_cpu()[0]  # a copy: the bound output buffer is reused
            except Exception as error:  # onnxruntime raises its own types for a graph that cannot run this input
                self._binding = None  # bind afresh next time: a failed run must not leave a half-bound session
                raise ArchiveError(f"the model cannot run a 120x160 camera frame: {str(error)[:200]}") from None
        return np.asarray(output).reshape(-1)

    def _run_plain(self, observation: np.ndarray) -> np.ndarray:
        frame = np.asarray(observation, dtype=np.float32).reshape(1, observation.shape[0], observation.shape[1], 1)
        try:
            output = self.session.run([self.output_name], {self.input_name: frame})[0]
        except Exception as error:  # onnxruntime raises its own types for a graph that cannot run this input
            raise ArchiveError(f"the model cannot run a 120x160 camera frame: {str(error)[:200]}") from None
        # One frame in: [1, N] or (for graphs that drop the batch axis) [N] out; both are the N values.
        return np.asarray(output).reshape(-1)

    def _bound(self, height: int, width: int) -> Any:
        """The IOBinding for a (1, height, width, 1) float32 frame: input bound to `self._frame`, output
        allocated by onnxruntime (its shape is the model's business: 2 means or one score per action)."""
        if self._binding is None or self._frame is None or self._frame.shape != (1, height, width, 1):
            self._frame = np.zeros((1, height, width, 1), np.float32)
            binding = self.session.io_binding()
            binding.bind_cpu_input(self.input_name, self._frame)
            binding.bind_output(self.output_name, "cpu")
            self._binding = binding
        return self._binding

    def act(self, observation: np.ndarray) -> dict[str, float]:
        return self.action_from_output(self.raw_output(observation))

    def action_from_output(self, output: np.ndarray) -> dict[str, float]:
        output = np.asarray(output, dtype=np.float64).reshape(-1)
        if self.kind == "continuous":
            if output.shape[0] != 2:
                raise ArchiveError(f"a continuous model must output 2 means (steering, speed), this one outputs "
                                   f"{output.shape[0]}")
            steering, speed = output.tolist()  # Python floats: np.clip on a 2-vector costs more than the rest
            return {"steering_angle": _rescale(_clip_unit(steering), self.action_space["steering_angle"]),
                    "speed": _rescale(_clip_unit(speed), self.action_space["speed"])}
        if output.shape[0] != len(self.action_space):
            raise ArchiveError(f"model outputs {output.shape[0]} values but the action space lists "
                               f"{len(self.action_space)} actions")
        chosen = self.action_space[int(np.argmax(output))]
        return {"steering_angle": float(chosen["steering_angle"]), "speed": float(chosen["speed"])}


def _converted(pb: bytes, metadata: dict[str, Any]) -> bytes:
    """The console graph as ONNX (OpenVINO reads it, both runtimes must agree), or TensorFlowModelError saying why."""
    import importlib.util
    import tempfile

    if importlib.util.find_spec("openvino") is None:
        raise TensorFlowModelError("cannot scrutineer: TensorFlow model (agent/model.pb) and the model converter "
                                   "(OpenVINO, the 'convert' extra) is not installed")
    from drem_sim.console.convert import convert

    with tempfile.TemporaryDirectory(prefix="console-model-") as folder:
        pb_path, onnx_path = Path(folder) / "model.pb", Path(folder) / "model.onnx"
        pb_path.write_bytes(pb)
        result = convert(pb_path, metadata, onnx_path)
        if result.outcome == "not_raceable":  # not the simulator's limit: no car could run it either
            raise NotRaceableModel(str(result.reason), result.detail)
        if result.outcome != "converted":
            raise TensorFlowModelError(f"cannot scrutineer: {result.reason}")
        return onnx_path.read_bytes()


def _clip_unit(value: float) -> float:
    """np.clip(value, -1, 1) for one float (NaN stays NaN, as np.clip leaves it)."""
    return -1.0 if value < -1.0 else (1.0 if value > 1.0 else value)


def _rescale(unit: float, bounds: dict[str, float]) -> float:
    low, high = float(bounds["low"]), float(bounds["high"])
    return float(low + (unit + 1.0) * 0.5 * (high - low))
