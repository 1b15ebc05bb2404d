"""Extracting an AVAILABLE model archive's regular files into a fresh sandbox, after the very same scan."""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import IO

from pydantic import BaseModel

from chalicelib.core.errors import InvalidInput
from chalicelib.formats.model_archive.layout import METADATA_FALLBACK_MEMBER, METADATA_MEMBER
from chalicelib.formats.model_archive.limits import DEFAULT_LIMITS, ArchiveLimits
from chalicelib.formats.model_archive.report import ArchiveReport, not_valid, quarantine
from chalicelib.formats.model_archive.safe_tar import ArchiveSource
from chalicelib.formats.model_archive.verdict import judge_archive


class ExtractedArchive(BaseModel):
    root: Path
    report: ArchiveReport

    @property
    def model_path(self) -> Path:
        assert self.report.model_member is not None
        return self.root / self.report.model_member

    @property
    def metadata_path(self) -> Path:
        return self.root / (METADATA_MEMBER if (self.root / METADATA_MEMBER).is_file() else METADATA_FALLBACK_MEMBER)


class ArchiveRejected(InvalidInput):
    """`safe_extract` refused an archive; `report` says why (QUARANTINED or NOT_VALID)."""

    def __init__(self, report: ArchiveReport) -> None:
        super().__init__(report.reason or "the model archive was rejected", field="archive")
        self.report = report


def safe_extract(
    source: ArchiveSource, dest_dir: str | os.PathLike[str], *, limits: ArchiveLimits = DEFAULT_LIMITS
) -> ExtractedArchive:
    """Extract an AVAILABLE archive's regular files into a new temporary directory under `dest_dir`.

    Every member is checked again while streaming; links, devices and escaping paths are never created, file modes
    from the archive are ignored. On any verdict other than AVAILABLE the sandbox is removed and ArchiveRejected
    raised, so a caller never sees a half-extracted model.
    """
    parent = Path(dest_dir)
    parent.mkdir(parents=True, exist_ok=True)
    sandbox = Path(tempfile.mkdtemp(prefix="model-", dir=parent)).resolve()
    try:
        report = judge_archive(source, limits=limits, open_output=_SandboxWriter(sandbox))
    except BaseException:
        shutil.rmtree(sandbox, ignore_errors=True)
        raise
    if not report.available:
        shutil.rmtree(sandbox, ignore_errors=True)
        raise ArchiveRejected(report)
    return ExtractedArchive(root=sandbox, report=report)


class _SandboxWriter:
    """Creates files for already-vetted member names below `root`, refusing to follow or replace anything."""

    def __init__(self, root: Path) -> None:
        self._root = root

    def __call__(self, name: str) -> IO[bytes]:
        target = self._root.joinpath(*name.split("/"))
        if not target.resolve().is_relative_to(self._root):  # second line of defence; the scanner already checked
            raise quarantine(f"member {name!r} would be written outside the sandbox")
        directory = self._root
        for part in name.split("/")[:-1]:
            directory = directory / part
            try:
                directory.mkdir(mode=0o755)
            except FileExistsError:
                if directory.is_symlink() or not directory.is_dir():
                    raise not_valid(f"member {name!r} needs {part!r} to be a folder, but it is a file") from None
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
        try:
            descriptor = os.open(target, flags, 0o644)
        except FileExistsError:
            raise not_valid(f"the archive holds {name!r} twice") from None
        return os.fdopen(descriptor, "wb")
