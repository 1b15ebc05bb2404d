"""The `model_metadata.json` that ships inside every DeepRacer model archive, as a typed, validated model.

The rules follow what the DeepRacer simulator and car read (see deepracer-formats.md §1.3): a discrete action space
is a list of {steering_angle, speed}, a continuous one is {steering_angle: {low, high}, speed: {low, high}}; exactly
one camera; at most one lidar. drem's own models (trained in drem_sim, exported to ONNX) name their network
`DREM_...` and may use `behaviour_cloning`. Keys we do not know are kept, so a round trip never loses a racer's data.
"""
from __future__ import annotations

import json
import re
from enum import StrEnum
from typing import Annotated, Any

from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from chalicelib.core.errors import InvalidInput

# Console limits (simapp agent_ctrl/constants.py): steering in degrees, positive = left; speed in m/s.
MAX_STEERING_DEG = 30.0
MIN_SPEED_MPS = 0.1
MAX_SPEED_MPS = 4.0

CAMERA_SENSORS = frozenset({"FRONT_FACING_CAMERA", "LEFT_CAMERA", "STEREO_CAMERAS", "observation"})
LIDAR_SENSORS = frozenset({"LIDAR", "SECTOR_LIDAR", "DISCRETIZED_SECTOR_LIDAR"})
DEEPRACER_NETWORKS = frozenset(
    {"DEEP_CONVOLUTIONAL_NETWORK_SHALLOW", "DEEP_CONVOLUTIONAL_NETWORK", "DEEP_CONVOLUTIONAL_NETWORK_DEEP"}
)
DREM_NETWORK_PATTERN = re.compile(r"DREM_[A-Z0-9_]{1,60}")
VERSION_PATTERN = re.compile(r"\d{1,3}(\.\d{1,3})?")

Steering = Annotated[float, Field(strict=True, ge=-MAX_STEERING_DEG, le=MAX_STEERING_DEG, allow_inf_nan=False)]
Speed = Annotated[float, Field(strict=True, ge=MIN_SPEED_MPS, le=MAX_SPEED_MPS, allow_inf_nan=False)]


class ActionSpaceType(StrEnum):
    DISCRETE = "discrete"
    CONTINUOUS = "continuous"


class TrainingAlgorithm(StrEnum):
    CLIPPED_PPO = "clipped_ppo"
    SAC = "sac"
    BEHAVIOUR_CLONING = "behaviour_cloning"  # drem's learning-from-demonstration models


class ModelMetadataError(InvalidInput):
    """`model_metadata.json` is not JSON, or breaks a rule; `field` is the dotted path of the first bad field."""


class DiscreteAction(BaseModel):
    model_config = ConfigDict(extra="allow")

    steering_angle: Steering
    speed: Speed
    index: Annotated[int, Field(strict=True, ge=0)] | None = None


class SteeringRange(BaseModel):
    model_config = ConfigDict(extra="allow")

    low: Steering
    high: Steering

    @model_validator(mode="after")
    def _low_below_high(self) -> SteeringRange:
        if self.low >= self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self


class SpeedRange(BaseModel):
    model_config = ConfigDict(extra="allow")

    low: Speed
    high: Speed

    @model_validator(mode="after")
    def _low_below_high(self) -> SpeedRange:
        if self.low >= self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self


class ContinuousActionSpace(BaseModel):
    model_config = ConfigDict(extra="allow")

    steering_angle: SteeringRange
    speed: SpeedRange


def _action_space_shape(value: Any) -> str | None:
    if isinstance(value, list):
        return ActionSpaceType.DISCRETE.value
    if isinstance(value, dict | ContinuousActionSpace):
        return ActionSpaceType.CONTINUOUS.value
    return None


ActionSpace = Annotated[
    Annotated[list[DiscreteAction], Tag(ActionSpaceType.DISCRETE.value), Field(min_length=1)]
    | Annotated[ContinuousActionSpace, Tag(ActionSpaceType.CONTINUOUS.value)],
    Discriminator(
        _action_space_shape,
        custom_error_type="action_space_shape",
        custom_error_message="must be a list of actions (discrete) or an object with steering_angle and speed ranges "
        "(continuous)",
    ),
]


class LidarConfig(BaseModel):
    model_config = ConfigDict(extra="allow")

    num_sectors: Annotated[int, Field(strict=True, ge=1, le=360)] | None = None
    num_values_per_sector: Annotated[int, Field(strict=True, ge=1, le=360)] | None = None
    clipping_dist: Annotated[float, Field(strict=True, gt=0, le=20, allow_inf_nan=False)] | None = None


class ModelMetadata(BaseModel):
    model_config = ConfigDict(extra="allow")

    action_space: ActionSpace
    action_space_type: ActionSpaceType = Field(default=ActionSpaceType.DISCRETE, validate_default=True)
    sensor: list[str] = Field(default_factory=lambda: ["observation"], validate_default=True)
    neural_network: str = "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"
    training_algorithm: TrainingAlgorithm = TrainingAlgorithm.CLIPPED_PPO
    version: str | None = None
    lidar_config: LidarConfig | None = None

    @field_validator("action_space")
    @classmethod
    def _indices_cover_every_action(cls, value: list[DiscreteAction] | ContinuousActionSpace):
        if isinstance(value, list):
            indices = [action.index for action in value]
            given = [index for index in indices if index is not None]
            # The index is the network output the car picks; a gap or a repeat would drive the wrong action.
            if given and sorted(given) != list(range(len(value))):
                raise ValueError(f"action indices must be 0..{len(value) - 1}, each once, on every action or on none")
        return value

    @field_validator("action_space_type")
    @classmethod
    def _type_matches_shape(cls, value: ActionSpaceType, info: ValidationInfo) -> ActionSpaceType:
        action_space = info.data.get("action_space")
        if action_space is None:
            return value  # action_space itself failed; that error is the useful one
        shape = ActionSpaceType(_action_space_shape(action_space))
        if shape != value:
            raise ValueError(f"is '{value.value}' but action_space is {shape.value} (missing means discrete)")
        return value

    @field_validator("sensor")
    @classmethod
    def _one_camera_at_most_one_lidar(cls, value: list[str]) -> list[str]:
        unknown = [name for name in value if name not in CAMERA_SENSORS | LIDAR_SENSORS]
        if unknown:
            known = ", ".join(sorted(CAMERA_SENSORS | LIDAR_SENSORS))
            raise ValueError(f"unknown sensor {unknown[0]!r} (known: {known})")
        if len(set(value)) != len(value):
            raise ValueError("lists a sensor twice")
        cameras = [name for name in value if name in CAMERA_SENSORS]
        if len(cameras) != 1:
            raise ValueError(f"needs exactly one camera of {', '.join(sorted(CAMERA_SENSORS))}; found {len(cameras)}")
        if sum(name in LIDAR_SENSORS for name in value) > 1:
            raise ValueError("may hold at most one lidar")
        return value

    @field_validator("neural_network")
    @classmethod
    def _known_network(cls, value: str) -> str:
        if value in DEEPRACER_NETWORKS or DREM_NETWORK_PATTERN.fullmatch(value):
            return value
        raise ValueError(f"must be one of {', '.join(sorted(DEEPRACER_NETWORKS))} or a drem network named DREM_...")

    @field_validator("version", mode="before")
    @classmethod
    def _version_string(cls, value: Any) -> Any:
        if isinstance(value, int) and not isinstance(value, bool):
            value = str(value)  # some producers write the version as a bare number
        if isinstance(value, str) and not VERSION_PATTERN.fullmatch(value):
            raise ValueError(f"must look like '5' or '5.1', got {value[:20]!r}")
        return value

    @property
    def camera(self) -> str:
        return next(name for name in self.sensor if name in CAMERA_SENSORS)

    @property
    def training_origin(self) -> str:
        """The algorithm that really trained the model. drem's exports name `clipped_ppo` for the car (the only
        algorithm a DeepRacer accepts beside sac) and keep the truth in `drem.training_algorithm`."""
        drem = getattr(self, "drem", None)
        real = drem.get("training_algorithm") if isinstance(drem, dict) else None
        return real if real in {algorithm.value for algorithm in TrainingAlgorithm} else self.training_algorithm.value

    @property
    def lidar(self) -> str | None:
        return next((name for name in self.sensor if name in LIDAR_SENSORS), None)

    @property
    def action_count(self) -> int | None:
        """Number of discrete actions (the policy's output size); None for a continuous space."""
        return len(self.action_space) if isinstance(self.action_space, list) else None


# What a stock car accepts (aws-deepracer-webserver-pkg webserver_pkg/constants.py: TrainingAlgorithms,
# SensorInputKeys, ActionSpaceTypes): the car refuses a model whose metadata names anything else.
CAR_TRAINING_ALGORITHMS = frozenset({TrainingAlgorithm.CLIPPED_PPO, TrainingAlgorithm.SAC})
CAR_SENSORS = frozenset({"observation", "LIDAR", "SECTOR_LIDAR", "LEFT_CAMERA", "FRONT_FACING_CAMERA",
                         "STEREO_CAMERAS"})


def check_for_stock_car(metadata: ModelMetadata) -> None:
    """Raise ModelMetadataError when a DeepRacer car would refuse a TensorFlow model with this metadata."""
    if metadata.training_algorithm not in CAR_TRAINING_ALGORITHMS:
        raise ModelMetadataError(
            f"model_metadata.json: training_algorithm: a DeepRacer car loads only clipped_ppo or sac models "
            f"(got {metadata.training_algorithm.value!r})", field="training_algorithm")
    unknown = [name for name in metadata.sensor if name not in CAR_SENSORS]
    if unknown:
        raise ModelMetadataError(
            f"model_metadata.json: sensor: a DeepRacer car does not know {unknown[0]!r} "
            f"(it knows {', '.join(sorted(CAR_SENSORS))})", field="sensor")


def parse_model_metadata(document: Any) -> ModelMetadata:
    """Validate an already-decoded JSON document; raise ModelMetadataError naming the field at fault."""
    if not isinstance(document, dict):
        raise ModelMetadataError("model_metadata.json must hold a JSON object", field="model_metadata.json")
    try:
        return ModelMetadata.model_validate(document)
    except ValidationError as error:
        raise _explain(error) from None


def parse_model_metadata_json(raw: bytes | str) -> ModelMetadata:
    """Decode strictly (UTF-8, no NaN/Infinity, no repeated keys, bounded nesting) and validate."""
    try:
        text = raw.decode("utf-8-sig") if isinstance(raw, bytes) else raw
    except UnicodeDecodeError:
        raise ModelMetadataError("model_metadata.json is not UTF-8 text", field="model_metadata.json") from None
    try:
        document = json.loads(text, object_pairs_hook=_reject_repeated_keys, parse_constant=_reject_constant)
    except json.JSONDecodeError as error:
        raise ModelMetadataError(
            f"model_metadata.json is not valid JSON: {error.msg} at line {error.lineno} column {error.colno}",
            field="model_metadata.json",
        ) from None
    except RecursionError:
        raise ModelMetadataError("model_metadata.json is nested too deeply", field="model_metadata.json") from None
    except ValueError as error:  # raised by the two hooks
        raise ModelMetadataError(f"model_metadata.json: {error}", field="model_metadata.json") from None
    return parse_model_metadata(document)


def _reject_repeated_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    # Two readers could pick different copies of a repeated key; refuse the ambiguity instead.
    document: dict[str, Any] = {}
    for key, value in pairs:
        if key in document:
            raise ValueError(f"key {key!r} appears twice")
        document[key] = value
    return document


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def _explain(error: ValidationError) -> ModelMetadataError:
    problems = [(_dotted(item["loc"]), _described(item)) for item in error.errors(include_url=False)]
    message = "; ".join(f"{field}: {text}" for field, text in problems[:3])
    if len(problems) > 3:
        message += f" (and {len(problems) - 3} more)"
    return ModelMetadataError(f"model_metadata.json: {message}", field=problems[0][0])


def _described(item: Any) -> str:
    text = item["msg"].removeprefix("Value error, ")
    given = item.get("input")
    shown = repr(given)
    if isinstance(given, int | float | str) and not isinstance(given, bool) and len(shown) <= 40 and shown not in text:
        text += f" (got {shown})"
    return text


def _dotted(location: tuple[int | str, ...]) -> str:
    parts: list[str] = []
    for step in location:
        if step in (ActionSpaceType.DISCRETE.value, ActionSpaceType.CONTINUOUS.value) and parts == ["action_space"]:
            continue  # union tag, not a field the racer wrote
        if isinstance(step, int):
            parts[-1] = f"{parts[-1]}[{step}]" if parts else f"[{step}]"
        else:
            parts.append(step)
    return ".".join(parts) or "model_metadata.json"


__all__ = [
    "ActionSpaceType",
    "CAMERA_SENSORS",
    "ContinuousActionSpace",
    "DiscreteAction",
    "LIDAR_SENSORS",
    "LidarConfig",
    "ModelMetadata",
    "ModelMetadataError",
    "TrainingAlgorithm",
    "check_for_stock_car",
    "parse_model_metadata",
    "parse_model_metadata_json",
]
