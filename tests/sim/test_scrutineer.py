"""Scrutineering uploaded archives: console TensorFlow models are reported, broken archives refused."""
from __future__ import annotations

import io
import json
import tarfile
from pathlib import Path

import pytest

from drem_sim.learn.scrutineer import scrutineer

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


def test_console_tensorflow_model_is_reported_as_not_scrutineerable(tmp_path: Path) -> None:
    archive = _archive(tmp_path / "console-model.tar.gz", {
        "model_metadata.json": json.dumps(CONSOLE_METADATA).encode(),
        "agent/model.pb": b"\x0a\x0bfrozen-graph-bytes",
    })

    report = scrutineer(archive, "reinvent_base", laps=1)

    assert report.verdict == "cannot_scrutineer"
    assert report.message.startswith("cannot scrutineer: TensorFlow model")
    assert report.completion_pct is None


def test_archive_without_metadata_is_invalid_with_a_clear_reason(tmp_path: Path) -> None:
    archive = _archive(tmp_path / "no-metadata.tar.gz", {"model.onnx": b"onnx"})

    report = scrutineer(archive, "reinvent_base", laps=1)

    assert report.verdict == "invalid"
    assert "no model_metadata.json" in report.message
