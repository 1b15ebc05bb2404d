"""`model_metadata.json` rules: what real producers write is accepted as written; what a car could not drive is
refused with a message that names the field."""
from __future__ import annotations

import json

import pytest

from chalicelib.core.errors import InvalidInput
from chalicelib.formats.model_metadata import (
    ActionSpaceType,
    ModelMetadataError,
    TrainingAlgorithm,
    parse_model_metadata,
    parse_model_metadata_json,
)

pytestmark = pytest.mark.unit

FIVE_ACTIONS = [{"steering_angle": angle, "speed": 0.6} for angle in (-30, -15, 0, 15, 30)]
CONTINUOUS = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 1, "high": 2}}


def refused(document: dict) -> ModelMetadataError:
    with pytest.raises(ModelMetadataError) as error:
        parse_model_metadata(document)
    return error.value


def test_drfc_default_discrete_metadata_is_read_as_written() -> None:
    metadata = parse_model_metadata({
        "action_space": FIVE_ACTIONS, "sensor": ["FRONT_FACING_CAMERA"],
        "neural_network": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW", "training_algorithm": "clipped_ppo",
        "action_space_type": "discrete", "version": "5",
    })

    assert metadata.action_count == 5
    assert [action.steering_angle for action in metadata.action_space] == [-30, -15, 0, 15, 30]
    assert metadata.camera == "FRONT_FACING_CAMERA" and metadata.lidar is None
    assert metadata.version == "5"


def test_deepracer_defaults_apply_to_missing_keys() -> None:
    metadata = parse_model_metadata({"action_space": FIVE_ACTIONS})

    assert metadata.action_space_type is ActionSpaceType.DISCRETE
    assert metadata.sensor == ["observation"]
    assert metadata.training_algorithm is TrainingAlgorithm.CLIPPED_PPO
    assert metadata.neural_network == "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"


def test_continuous_sac_with_lidar_and_numeric_version() -> None:
    metadata = parse_model_metadata({
        "action_space": CONTINUOUS, "action_space_type": "continuous", "training_algorithm": "sac",
        "sensor": ["STEREO_CAMERAS", "SECTOR_LIDAR"], "version": 4,
        "lidar_config": {"num_sectors": 8, "num_values_per_sector": 8, "clipping_dist": 2.0},
    })

    assert metadata.action_count is None
    assert metadata.action_space.speed.high == 2
    assert (metadata.camera, metadata.lidar) == ("STEREO_CAMERAS", "SECTOR_LIDAR")
    assert metadata.version == "4"


def test_drem_networks_and_behaviour_cloning_are_ours_to_name() -> None:
    metadata = parse_model_metadata({"action_space": FIVE_ACTIONS, "neural_network": "DREM_SMALL_CNN",
                                     "training_algorithm": "behaviour_cloning"})

    assert metadata.neural_network == "DREM_SMALL_CNN"
    assert metadata.training_algorithm is TrainingAlgorithm.BEHAVIOUR_CLONING


def test_unknown_keys_survive_a_round_trip() -> None:
    document = {"action_space": FIVE_ACTIONS, "preprocess_type": "GREY_SCALE", "drem": {"scale": "raw"}}

    dumped = parse_model_metadata(document).model_dump(mode="json")

    assert dumped["preprocess_type"] == "GREY_SCALE" and dumped["drem"] == {"scale": "raw"}


def test_indexed_actions_must_cover_every_output_once() -> None:
    indexed = [{**action, "index": i} for i, action in enumerate(FIVE_ACTIONS)]
    assert parse_model_metadata({"action_space": indexed}).action_count == 5

    gap = [{**action, "index": i * 2} for i, action in enumerate(FIVE_ACTIONS)]
    assert refused({"action_space": gap}).field == "action_space"
    partial = [{**FIVE_ACTIONS[0], "index": 0}, FIVE_ACTIONS[1]]
    assert "each once" in refused({"action_space": partial}).message


@pytest.mark.parametrize(
    ("document", "field", "words"),
    [
        ({}, "action_space", "Field required"),
        ({"action_space": []}, "action_space", "at least 1"),
        ({"action_space": "fast"}, "action_space", "list of actions"),
        ({"action_space": [{"steering_angle": 31, "speed": 1}]}, "action_space[0].steering_angle", "30"),
        ({"action_space": [{"steering_angle": 0, "speed": 1}, {"steering_angle": 0, "speed": 0.05}]},
         "action_space[1].speed", "0.1"),
        ({"action_space": [{"steering_angle": 0, "speed": "1"}]}, "action_space[0].speed", "valid number"),
        ({"action_space": [{"steering_angle": True, "speed": 1}]}, "action_space[0].steering_angle", "valid number"),
        ({"action_space": [{"speed": 1}]}, "action_space[0].steering_angle", "Field required"),
        ({"action_space": {**CONTINUOUS, "speed": {"low": 2, "high": 1}}, "action_space_type": "continuous"},
         "action_space.speed", "below high"),
        ({"action_space": {**CONTINUOUS, "steering_angle": {"low": -45, "high": 30}},
          "action_space_type": "continuous"}, "action_space.steering_angle.low", "-30"),
        ({"action_space": CONTINUOUS}, "action_space_type", "continuous"),
        ({"action_space": FIVE_ACTIONS, "action_space_type": "continuous"}, "action_space_type", "discrete"),
        ({"action_space": FIVE_ACTIONS, "action_space_type": "fuzzy"}, "action_space_type", "'fuzzy'"),
        ({"action_space": FIVE_ACTIONS, "sensor": ["LIDAR"]}, "sensor", "exactly one camera"),
        ({"action_space": FIVE_ACTIONS, "sensor": ["FRONT_FACING_CAMERA", "LEFT_CAMERA"]}, "sensor",
         "exactly one camera"),
        ({"action_space": FIVE_ACTIONS, "sensor": ["observation", "LIDAR", "SECTOR_LIDAR"]}, "sensor", "one lidar"),
        ({"action_space": FIVE_ACTIONS, "sensor": ["observation", "SONAR"]}, "sensor", "'SONAR'"),
        ({"action_space": FIVE_ACTIONS, "sensor": ["observation", "observation"]}, "sensor", "twice"),
        ({"action_space": FIVE_ACTIONS, "neural_network": "RESNET_50"}, "neural_network", "DREM_"),
        ({"action_space": FIVE_ACTIONS, "neural_network": "DREM_lower"}, "neural_network", "DREM_"),
        ({"action_space": FIVE_ACTIONS, "training_algorithm": "dqn"}, "training_algorithm", "'dqn'"),
        ({"action_space": FIVE_ACTIONS, "version": "five"}, "version", "'five'"),
        ({"action_space": FIVE_ACTIONS, "lidar_config": {"num_sectors": 0}}, "lidar_config.num_sectors", "1"),
    ],
)
def test_rule_breaks_name_the_field(document: dict, field: str, words: str) -> None:
    error = refused(document)

    assert error.field == field
    assert isinstance(error, InvalidInput)
    assert error.message.startswith(f"model_metadata.json: {field}: ")
    assert words in error.message


def test_several_problems_are_reported_together() -> None:
    error = refused({"action_space": [{"steering_angle": 99, "speed": 9}], "sensor": ["SONAR"]})

    assert "action_space[0].steering_angle" in error.message
    assert "action_space[0].speed" in error.message
    assert "sensor" in error.message


@pytest.mark.parametrize(
    ("raw", "words"),
    [
        (b'{"action_space": ', "not valid JSON"),
        (b"\xff\xfe{}", "not UTF-8"),
        (b'{"action_space": [{"steering_angle": NaN, "speed": 1}]}', "NaN"),
        (b'{"action_space": [], "action_space": [{"steering_angle": 0, "speed": 1}]}', "appears twice"),
        (b'"just a string"', "JSON object"),
        (b"[" * 50_000 + b"]" * 50_000, "nested too deeply"),
    ],
)
def test_json_that_is_not_plain_metadata_is_refused(raw: bytes, words: str) -> None:
    with pytest.raises(ModelMetadataError) as error:
        parse_model_metadata_json(raw)

    assert words in error.value.message
    assert error.value.field == "model_metadata.json"


def test_json_with_a_byte_order_mark_is_read() -> None:
    raw = b"\xef\xbb\xbf" + json.dumps({"action_space": FIVE_ACTIONS}).encode()

    assert parse_model_metadata_json(raw).action_count == 5


def test_a_drem_export_names_clipped_ppo_for_the_car_but_keeps_its_real_origin() -> None:
    document = {"action_space": {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2.0}},
                "action_space_type": "continuous", "sensor": ["FRONT_FACING_CAMERA"],
                "neural_network": "DREM_BC_CNN_SMALL", "training_algorithm": "clipped_ppo",
                "drem": {"training_algorithm": "behaviour_cloning", "car_model_file": "agent/model.pb"}}
    metadata = parse_model_metadata(document)
    assert metadata.training_algorithm.value == "clipped_ppo"  # what the car validates
    assert metadata.training_origin == "behaviour_cloning"  # what drem shows
    assert parse_model_metadata({**document, "drem": {"training_algorithm": "magic"}}).training_origin == "clipped_ppo"
