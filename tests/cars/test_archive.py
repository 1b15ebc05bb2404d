from __future__ import annotations

import gzip
import hashlib
from pathlib import Path

import pytest

from drem_cars.archive import UnsafeArchive, safe_extract
from drem_cars.model_store import ModelInstallError, ModelStore
from tests.unit.models_helpers import onnx_archive, tar_gz, traversal_archive

pytestmark = pytest.mark.unit


def write(tmp_path: Path, data: bytes) -> Path:
    path = tmp_path / "a.tar.gz"
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("data, reason", [
    (traversal_archive(), "climbs out of the archive"),
    (tar_gz([("model.onnx", b"x")], symlinks={"model_metadata.json": "/etc/passwd"}), "is a symbolic link"),
    (tar_gz([("/abs/model.onnx", b"x")]), "has an absolute path"),
    (tar_gz([("a.onnx", b"1"), ("a.onnx", b"2")]), "names a file twice"),
    (gzip.compress(b"not a tar at all" * 50, mtime=0), "not a readable"),
], ids=["traversal", "symlink", "absolute", "duplicate", "not-a-tar"])
def test_hostile_members_are_refused_and_nothing_lands_outside(tmp_path: Path, data: bytes, reason: str) -> None:
    destination = tmp_path / "out"
    destination.mkdir()
    with pytest.raises(UnsafeArchive, match=reason):
        safe_extract(write(tmp_path, data), destination)
    assert not (tmp_path / "etc").exists()


def test_a_checksum_mismatch_installs_nothing(tmp_path: Path) -> None:
    store = ModelStore(tmp_path / "models")
    data = onnx_archive()
    with pytest.raises(ModelInstallError, match="checksum mismatch"):
        store.install("m1", "fast", "racer-fast", "0" * 32, download=lambda handle: handle.write(data[:-10]))
    assert store.installed() == {} and not any((tmp_path / "models" / ".staging").iterdir())
    model = store.install("m1", "fast", "racer-fast", hashlib.md5(data).hexdigest(),
                          download=lambda handle: handle.write(data))
    assert (model.path / "model.onnx").is_file() and store.installed()["m1"] == model
