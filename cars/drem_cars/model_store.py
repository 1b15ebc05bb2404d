"""The car's model store: assigned models are downloaded, verified and unpacked here, then swapped in atomically.

Layout under `<config dir>/models/`:
    <folder>@<md5 prefix>/      one unpacked model (model_metadata.json, model.onnx or agent/model.pb, ...)
        archive.tar.gz          the verified archive itself (a DeepRacer console takes the archive)
        .drem-model.json        which assignment it came from (model id, name, archive md5)
    .staging/                   downloads and extractions in progress; never loaded from

A half-downloaded model is never loaded: the archive is downloaded to .staging, its md5 checked against the
assignment, unpacked into a fresh .staging directory, and only then renamed into place (one atomic rename).
"""
from __future__ import annotations

import hashlib
import json
import re
import shutil
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import BinaryIO

from drem_cars.archive import safe_extract
from drem_cars.model_files import METADATA_FILE

MARKER = ".drem-model.json"
ARCHIVE_COPY = "archive.tar.gz"
STAGING = ".staging"


class ModelInstallError(RuntimeError):
    """The model could not be installed; the message is the reason reported to the server."""


@dataclass(frozen=True)
class InstalledModel:
    model_id: str
    name: str
    folder: str
    archive_md5: str
    path: Path

    def marker(self) -> dict[str, str]:
        data = asdict(self)
        data.pop("path")
        return data


def safe_folder(folder: str) -> str:
    cleaned = re.sub(r"[^A-Za-z0-9_-]", "_", folder)[:120]
    return cleaned or "model"


class ModelStore:
    def __init__(self, root: Path) -> None:
        self.root = root
        self.root.mkdir(parents=True, exist_ok=True)
        self._staging = root / STAGING
        shutil.rmtree(self._staging, ignore_errors=True)  # leftovers of an interrupted install are never trusted
        self._staging.mkdir()

    def installed(self) -> dict[str, InstalledModel]:
        """model_id → installed model (only complete installs: the marker is written before the final rename)."""
        found: dict[str, InstalledModel] = {}
        for directory in sorted(self.root.iterdir()):
            marker = directory / MARKER
            if directory.name.startswith(".") or not marker.is_file():
                continue
            data = json.loads(marker.read_text())
            found[data["model_id"]] = InstalledModel(**data, path=directory)
        return found

    def find(self, model_id: str, archive_md5: str) -> InstalledModel | None:
        model = self.installed().get(model_id)
        return model if model is not None and model.archive_md5 == archive_md5 else None

    def install(self, model_id: str, name: str, folder: str, expected_md5: str,
                download: Callable[[BinaryIO], None], on_verified: Callable[[str], None] | None = None,
                converted: tuple[Callable[[BinaryIO], None], str] | None = None) -> InstalledModel:
        """`converted`: (download, md5) of the server's ONNX conversion of a console model (agent/model.pb), added
        as model.onnx so the drem agent can drive it; the archive itself stays as the console downloaded it."""
        work = self._staging / uuid.uuid4().hex
        work.mkdir()
        try:
            archive = work / ARCHIVE_COPY
            with open(archive, "wb") as handle:
                download(handle)
            actual = md5_of(archive)
            if actual != expected_md5:
                raise ModelInstallError(f"checksum mismatch: downloaded archive md5 {actual}, expected {expected_md5}")
            if on_verified is not None:
                on_verified(actual)
            unpacked = work / "model"
            unpacked.mkdir()
            try:
                safe_extract(archive, unpacked)
            except ValueError as exc:
                raise ModelInstallError(f"unsafe or broken archive: {exc}") from None
            if not (unpacked / METADATA_FILE).is_file():
                raise ModelInstallError(f"the archive has no {METADATA_FILE}")
            if converted is not None and not (unpacked / "model.onnx").exists():
                _fetch_verified(unpacked / "model.onnx", *converted)
            shutil.move(str(archive), unpacked / ARCHIVE_COPY)
            final = self.root / f"{safe_folder(folder)}@{actual[:12]}"
            model = InstalledModel(model_id=model_id, name=name, folder=safe_folder(folder), archive_md5=actual,
                                   path=final)
            (unpacked / MARKER).write_text(json.dumps(model.marker()))
            if final.exists():
                shutil.rmtree(final)
            unpacked.rename(final)  # the one atomic step that makes the model visible
            self._drop_other_versions(model)
            return model
        finally:
            shutil.rmtree(work, ignore_errors=True)

    def _drop_other_versions(self, keep: InstalledModel) -> None:
        for model in self._all_markers():
            if model.model_id == keep.model_id and model.path != keep.path:
                shutil.rmtree(model.path, ignore_errors=True)

    def _all_markers(self) -> list[InstalledModel]:
        models = []
        for directory in self.root.iterdir():
            marker = directory / MARKER
            if not directory.name.startswith(".") and marker.is_file():
                models.append(InstalledModel(**json.loads(marker.read_text()), path=directory))
        return models

    def remove_except(self, keep_ids: set[str]) -> list[str]:
        removed = []
        for model in self._all_markers():
            if model.model_id not in keep_ids:
                shutil.rmtree(model.path, ignore_errors=True)
                removed.append(model.model_id)
        return removed

    def delete_all(self) -> int:
        models = self._all_markers()
        for model in models:
            shutil.rmtree(model.path, ignore_errors=True)
        return len(models)


def _fetch_verified(target: Path, download: Callable[[BinaryIO], None], expected_md5: str) -> None:
    with open(target, "wb") as handle:
        download(handle)
    actual = md5_of(target)
    if actual != expected_md5:
        raise ModelInstallError(f"checksum mismatch: downloaded model.onnx md5 {actual}, expected {expected_md5}")


def md5_of(path: Path) -> str:
    digest = hashlib.md5(usedforsecurity=False)
    with open(path, "rb") as handle:
        while piece := handle.read(1 << 20):
            digest.update(piece)
    return digest.hexdigest()
