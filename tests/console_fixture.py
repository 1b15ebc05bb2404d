"""The real-structure console model in ../shared/deepracer-models (see its SOURCE.md), for tests and benches."""
from __future__ import annotations

import io
import json
import tarfile
from pathlib import Path

import pytest

from tests.conftest import REPO_ROOT

FIXTURE_DIR = REPO_ROOT.parent / "shared" / "deepracer-models" / "console-discrete-shallow-ppo"
ARCHIVE = FIXTURE_DIR / "console-discrete-shallow-ppo.tar.gz"
FRAMES = FIXTURE_DIR / "frames.npy"
EXPECTED = FIXTURE_DIR / "expected_outputs.npy"


def require_fixture() -> Path:
    if not ARCHIVE.is_file():
        pytest.fail(f"the shared console model fixture is missing at {ARCHIVE}")
    return ARCHIVE


def members() -> dict[str, bytes]:
    with tarfile.open(require_fixture(), "r:gz") as archive:
        return {m.name.removeprefix("./"): archive.extractfile(m).read() for m in archive if m.isreg()}


def console_archive(*, metadata: dict | None = None, pb: bytes | None = None, flat: bool = False,
                    extra: dict[str, bytes] | None = None) -> bytes:
    """The fixture repacked, optionally with other metadata or graph bytes, or in DROA's flat layout."""
    files = members()
    document = json.loads(files["model_metadata.json"])
    document.update(metadata or {})
    graph = files["agent/model.pb"] if pb is None else pb
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as archive:
        for name, data in (("model_metadata.json", json.dumps(document).encode()),
                           ("model.pb" if flat else "agent/model.pb", graph), *(extra or {}).items()):
            info = tarfile.TarInfo(name)
            info.size = len(data)
            archive.addfile(info, io.BytesIO(data))
    return buffer.getvalue()
