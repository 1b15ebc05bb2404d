"""What a model directory on the car holds, and DeepRacer's `model_metadata.json` action space (read, checked)."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

METADATA_FILE = "model_metadata.json"
ONNX_FILES = ("model.onnx", "agent/model.onnx")
TENSORFLOW_FILES = ("agent/model.pb", "model.pb")


class ModelError(ValueError):
    """The model cannot be run on this car; the message says why in plain words."""


class ConsoleModelError(ModelError):
    """A DeepRacer console (TensorFlow frozen graph) model: the drem agent runs ONNX only."""


@dataclass(frozen=True)
class ActionSpace:
    kind: str  # "discrete" | "continuous"
    actions: tuple[tuple[float, float], ...] = ()  # discrete: (steering_deg, speed)
    steering: tuple[float, float] = (0.0, 0.0)     # continuous: low, high
    speed: tuple[float, float] = (0.0, 0.0)

    # The car's own scales (aws-deepracer-navigation-pkg deepracer_navigation_node.py, set_action_space_scales):
    # discrete, the largest |steering| and the largest |speed| of the actions; continuous, `high` of each, whatever
    # `low` is. get_max_scaled_value divides by them; a scale <= 0 drives nothing (the node answers 0.0).
    @property
    def steering_scale(self) -> float:
        if self.kind == "continuous":
            return self.steering[1]
        return max(abs(a[0]) for a in self.actions)

    @property
    def max_speed(self) -> float:
        if self.kind == "continuous":
            return self.speed[1]
        return max(abs(a[1]) for a in self.actions)


def action_space_of(metadata: dict[str, Any]) -> ActionSpace:
    kind = str(metadata.get("action_space_type", "discrete"))  # DeepRacer's default when missing
    space: Any = metadata.get("action_space")  # checked by the parse below (bad shapes raise)
    try:
        if kind == "continuous":
            return ActionSpace("continuous", steering=_bounds(space["steering_angle"]), speed=_bounds(space["speed"]))
        if kind == "discrete":
            actions = tuple((float(a["steering_angle"]), float(a["speed"])) for a in space)
            if not actions:
                raise ValueError("empty list")
            return ActionSpace("discrete", actions=actions)
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"model_metadata.json: the {kind} action_space is not usable ({exc})") from None
    raise ModelError(f"model_metadata.json: unknown action_space_type {kind!r} (discrete or continuous)")


def _bounds(entry: dict[str, Any]) -> tuple[float, float]:
    return float(entry["low"]), float(entry["high"])


def read_metadata(model_dir: Path) -> dict[str, Any]:
    path = model_dir / METADATA_FILE
    try:
        metadata = json.loads(path.read_text())
    except FileNotFoundError:
        raise ModelError(f"{model_dir.name}: no {METADATA_FILE}") from None
    except (ValueError, OSError) as exc:
        raise ModelError(f"{model_dir.name}: {METADATA_FILE} is not valid JSON ({exc})") from None
    if not isinstance(metadata, dict):
        raise ModelError(f"{model_dir.name}: {METADATA_FILE} must be a JSON object")
    return metadata


def onnx_file(model_dir: Path) -> Path:
    for name in ONNX_FILES:
        if (model_dir / name).is_file():
            return model_dir / name
    if any((model_dir / name).is_file() for name in TENSORFLOW_FILES):
        raise ConsoleModelError(
            f"{model_dir.name} is a DeepRacer console model (TensorFlow agent/model.pb); the drem car agent runs "
            "ONNX models only. Load it on a DeepRacer through its device console, or export the model to ONNX.")
    raise ModelError(f"{model_dir.name}: no model.onnx in the model folder")
