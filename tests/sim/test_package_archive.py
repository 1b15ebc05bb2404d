"""Model archive packaging: DeepRacer metadata schema, member layout, name rule, hostile-archive reading."""
from __future__ import annotations

import io
import json
import tarfile
from pathlib import Path

import pytest

from drem_sim.learn.dataset import ActionScale
from drem_sim.learn.package import (
    ArchiveError,
    build_archive,
    build_metadata,
    load_metadata,
    read_model_files,
)

pytestmark = pytest.mark.sim


def test_metadata_follows_the_deepracer_continuous_schema_and_names_the_onnx_tensors() -> None:
    metadata = build_metadata(ActionScale(speed_low=0.8, speed_high=2.5))

    assert metadata["action_space_type"] == "continuous"
    assert metadata["action_space"] == {"steering_angle": {"low": -30.0, "high": 30.0},
                                        "speed": {"low": 0.8, "high": 2.5}}
    assert metadata["sensor"] == ["FRONT_FACING_CAMERA"]
    assert metadata["neural_network"] == "DREM_BC_CNN_SMALL"
    assert metadata["training_algorithm"] == "behaviour_cloning"
    assert metadata["version"] == "5"
    assert metadata["drem"]["input"]["name"] == "observation"
    assert metadata["drem"]["input"]["layout"] == "NHWC"
    assert metadata["drem"]["input"]["shape"] == [None, 120, 160, 1]
    assert metadata["drem"]["output"]["name"] == "policy"
    assert metadata["drem"]["output"]["order"] == ["steering_angle", "speed"]
    json.dumps(metadata)  # must serialise as plain JSON


def test_archive_holds_metadata_model_and_lineage_at_fixed_paths(tmp_path: Path) -> None:
    onnx_path = tmp_path / "model.onnx"
    onnx_path.write_bytes(b"onnx-bytes")
    archive = build_archive(tmp_path / "my_model-1.tar.gz", onnx_path, build_metadata(ActionScale()), {"seed": 3})

    with tarfile.open(archive) as tar:
        members = {m.name: m for m in tar.getmembers()}
    assert set(members) == {"model_metadata.json", "model.onnx", "training/lineage.json"}
    assert all(m.isreg() for m in members.values())
    files = read_model_files(archive)
    assert files["model.onnx"] == b"onnx-bytes"
    assert load_metadata(files)["action_space_type"] == "continuous"


@pytest.mark.parametrize("name", ["my model.tar.gz", "model.zip", "model.tar", "mödel.tar.gz"])
def test_archive_names_outside_the_upload_rule_are_refused(tmp_path: Path, name: str) -> None:
    onnx_path = tmp_path / "model.onnx"
    onnx_path.write_bytes(b"x")
    with pytest.raises(ArchiveError, match=r"\[A-Za-z0-9_-\]"):
        build_archive(tmp_path / name, onnx_path, build_metadata(ActionScale()), {})


def test_reading_a_hostile_archive_ignores_links_and_escaping_paths(tmp_path: Path) -> None:
    archive = tmp_path / "hostile.tar.gz"
    with tarfile.open(archive, "w:gz") as tar:
        _add(tar, "../model_metadata.json", b'{"action_space": []}')
        link = tarfile.TarInfo("model.onnx")
        link.type, link.linkname = tarfile.SYMTYPE, "/etc/passwd"
        tar.addfile(link)
        _add(tar, "./model_metadata.json", json.dumps(build_metadata(ActionScale())).encode())

    files = read_model_files(archive)

    assert set(files) == {"model_metadata.json"}
    assert not (tmp_path.parent / "model_metadata.json").exists()


def test_a_file_that_is_not_an_archive_gets_a_clear_error(tmp_path: Path) -> None:
    bogus = tmp_path / "bogus.tar.gz"
    bogus.write_bytes(b"definitely not gzip")
    with pytest.raises(ArchiveError, match="not a readable tar.gz archive"):
        read_model_files(bogus)


def _add(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    tar.addfile(info, io.BytesIO(data))
