"""Scrutineering uploaded archives: console TensorFlow models are reported, broken archives refused."""
from __future__ import annotations

import io
import json
import tarfile
from pathlib import Path

import pytest

from drem_sim.learn.dataset import ActionScale
from drem_sim.learn.package import build_metadata
from drem_sim.learn.scrutineer import scrutineer, scrutineer_for_event, track_for_event
from tests.sim.test_learn_pilot import _constant_policy

pytestmark = pytest.mark.sim

CONSOLE_METADATA = {"action_space": [{"steering_angle": -30, "speed": 0.6}, {"steering_angle": 30, "speed": 0.6}],
                    "sensor": ["FRONT_FACING_CAMERA"], "neural_network": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
                    "training_algorithm": "clipped_ppo", "action_space_type": "discrete", "version": "5"}


def _archive(path: Path, members: dict[str, bytes]) -> Path:
    with tarfile.open(path, "w:gz") as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return path


def test_a_console_graph_openvino_cannot_read_is_reported_as_not_scrutineerable(tmp_path: Path) -> None:
    archive = _archive(tmp_path / "console-model.tar.gz", {
        "model_metadata.json": json.dumps(CONSOLE_METADATA).encode(),
        "agent/model.pb": b"\x0a\x0bfrozen-graph-bytes",
    })

    report = scrutineer(archive, "reinvent_base", laps=1)

    assert report.verdict == "invalid"  # no car could load it either: not raceable
    assert report.message.startswith("This model cannot race: a stock car cannot load this model: its "
                                     "agent/model.pb is damaged or incomplete")
    assert "download the model again" in report.message  # what to do
    assert "Exception" not in report.message and "core.cpp" not in report.message  # no code names, no source lines
    assert "OpenVINO cannot read agent/model.pb" in (report.detail or "")
    assert report.completion_pct is None


def test_a_real_console_model_is_converted_and_driven(tmp_path: Path) -> None:
    from tests import console_fixture

    report = scrutineer(console_fixture.require_fixture(), "reinvent_base", laps=1)

    # Untrained (random) weights: it drives, badly; what matters is that it was driven and measured.
    assert report.verdict in ("passed", "failed"), report.message
    assert report.completion_pct is not None and report.offtrack_count >= 0
    assert "laps completed on reinvent_base" in report.message


def test_archive_without_metadata_is_invalid_with_a_clear_reason(tmp_path: Path) -> None:
    archive = _archive(tmp_path / "no-metadata.tar.gz", {"model.onnx": b"onnx"})

    report = scrutineer(archive, "reinvent_base", laps=1)

    assert report.verdict == "invalid"
    assert "no model_metadata.json" in report.message


SAMPLE = Path(__file__).resolve().parents[2] / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"


@pytest.mark.parametrize(("track_type", "track"), [
    ("REINVENT_2018", "reinvent_base"), ("ATOZ_SPEEDWAY", "reInvent2019_wide"),
    ("SUMMIT_SPEEDWAY", "2022_summit_speedway"), ("FOREVER_RACEWAY", "2024_reinvent_champ_ccw"),
    ("REINVENT_2019", "reInvent2019_track"),
])
def test_event_track_types_map_to_their_simulator_twin(track_type: str, track: str) -> None:
    from drem_sim.tracks import load_track

    mapped = track_for_event(track_type)
    assert mapped.track == track and mapped.note is None
    assert load_track(mapped.track).length > 10  # a real shipped track


def test_unknown_track_types_fall_back_to_reinvent_2018_with_a_note() -> None:
    mapped = track_for_event("REINVENT_2023")
    assert mapped.track == "reinvent_base"
    assert mapped.note == "no simulator track for REINVENT_2023; driven on reinvent_base"


def test_a_model_that_laps_passes_with_its_lap_times() -> None:
    report = scrutineer_for_event(SAMPLE, "REINVENT_2018", laps=2)

    assert report.verdict == "passed", report.message
    assert report.track == "reinvent_base" and report.track_type == "REINVENT_2018"
    assert report.completion_pct == 100.0 and report.laps_completed == 2
    assert len(report.lap_times_s) == 2 and all(7.0 < t < 20.0 for t in report.lap_times_s)
    assert report.message.startswith("2/2 laps completed on reinvent_base")


def test_a_model_that_leaves_the_track_fails_with_its_completion(tmp_path: Path) -> None:
    metadata = {**build_metadata(ActionScale(speed_low=1.0, speed_high=2.0))}
    archive = _archive(tmp_path / "hard-left.tar.gz", {
        "model_metadata.json": json.dumps(metadata).encode(),
        "model.onnx": _constant_policy([1.0, 1.0]),  # full left lock at top speed, whatever the camera sees
    })

    report = scrutineer(archive, "reinvent_base", laps=2)

    assert report.verdict == "failed"
    assert report.laps_completed == 0 and report.offtrack_count >= 1
    assert 0.0 <= report.completion_pct < 50.0
    assert report.message.startswith("0/2 laps completed")


def test_a_model_with_the_wrong_number_of_outputs_is_invalid_not_a_crash(tmp_path: Path) -> None:
    from onnx import TensorProto, helper

    image = helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 120, 160, 1])
    mean = helper.make_tensor_value_info("mean", TensorProto.FLOAT, [1])
    graph = helper.make_graph([helper.make_node("ReduceMean", ["image"], ["mean"], axes=[1, 2, 3], keepdims=0)],
                              "one_output", [image], [mean])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    continuous = {"action_space": {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2}},
                  "action_space_type": "continuous", "sensor": ["FRONT_FACING_CAMERA"]}
    archive = _archive(tmp_path / "one-output.tar.gz", {"model_metadata.json": json.dumps(continuous).encode(),
                                                        "model.onnx": model.SerializeToString()})

    report = scrutineer(archive, "reinvent_base", laps=1)

    assert report.verdict == "invalid"
    assert "must output 2 means" in report.message


def test_a_track_type_without_a_twin_says_which_real_track_stood_in() -> None:
    report = scrutineer_for_event(SAMPLE, "REINVENT_2022", laps=1)

    assert report.verdict in ("passed", "failed") and report.track == "reinvent_base"
    assert report.message.endswith("(no simulator track for REINVENT_2022; driven on reinvent_base)"), report.message
