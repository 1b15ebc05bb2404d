"""Reading a model export (a folder or a .tar.gz) into memory, with bounds: the files the league assembler needs.

An export is hostile input. Nothing is ever extracted to disk: a folder is walked without following links, an
archive is streamed member by member and only small regular files whose names the assembler asks for are read,
each capped, with caps on member count and on decompressed bytes (a gzip bomb stops at the cap). Names are
normalised ("./a/b" → "a/b"); a member refused by the one vetting of `drem_archive.member_names` (absolute
names, "..", backslashes, control or bidi characters, links, devices) is skipped, never read.
"""
from __future__ import annotations

import gzip
import io
import os
import tarfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from chalicelib.core.errors import InvalidInput, PayloadTooLarge
from drem_archive.member_names import RefusedMember, vet_member_name, vet_member_type

MiB = 1024 * 1024


@dataclass(frozen=True)
class ExportLimits:
    max_archive_bytes: int = 256 * MiB  # compressed size of a .tar.gz export
    max_expanded_bytes: int = 1024 * MiB  # decompressed bytes streamed past (sim-traces are big; bombs are bigger)
    max_members: int = 20_000
    max_file_bytes: int = 16 * MiB  # one JSON/YAML/log file we read
    max_total_read_bytes: int = 64 * MiB  # all files we read together
    max_depth: int = 12


DEFAULT_LIMITS = ExportLimits()


class ExportFiles:
    """The wanted files of one export: normalised relative name → bytes (the common top folder removed)."""

    def __init__(self, source_name: str, files: dict[str, bytes], names: list[str]) -> None:
        self.source_name = source_name
        self.files = files
        self.names = names  # every regular file seen, read or not (for layout detection and messages)

    def __contains__(self, name: str) -> bool:
        return name in self.files

    def read(self, name: str) -> bytes:
        return self.files[name]


def wanted_file(name: str) -> bool:
    """The files the assembler may read: text documents and the evaluations' sim-traces (their `track_len` and
    step times are the evaluation's evidence), never models, checkpoints or training sim-traces."""
    lowered = name.lower()
    return (lowered.endswith((".json", ".yaml", ".yml", ".log"))
            or "/evaluation-simtrace/" in f"/{lowered}" and lowered.endswith(".csv"))


def pack_exports(exports: list[ExportFiles]) -> bytes:
    """The files of one or more exports (a logs download and the model download, say) as one .tar.gz, for the
    server to assemble: names kept as each export has them; the same name in two exports is refused."""
    merged: dict[str, bytes] = {}
    for export in exports:
        for name, data in export.files.items():
            if name in merged and merged[name] != data:
                raise InvalidInput(f"{name} is in two of the exports with different content; push them one at a "
                                   "time", field="path")
            merged[name] = data
    buffer = io.BytesIO()
    with gzip.GzipFile(fileobj=buffer, mode="wb", mtime=0) as compressed, \
            tarfile.open(fileobj=compressed, mode="w", format=tarfile.PAX_FORMAT) as archive:
        for name in sorted(merged):
            info = tarfile.TarInfo(name)
            info.size = len(merged[name])
            info.mode = 0o644
            archive.addfile(info, io.BytesIO(merged[name]))
    return buffer.getvalue()


def read_export(path: str | Path, *, limits: ExportLimits = DEFAULT_LIMITS,
                wanted: Callable[[str], bool] = wanted_file) -> ExportFiles:
    source = Path(path)
    if source.is_dir():
        return _strip_common_top(source.name, *_read_folder(source, limits, wanted))
    if source.is_file():
        if source.stat().st_size > limits.max_archive_bytes:
            raise PayloadTooLarge(f"{source.name} is larger than {_size(limits.max_archive_bytes)}", field="path")
        with source.open("rb") as stream:
            name = source.name.removesuffix(".gz").removesuffix(".tar").removesuffix(".tgz")
            return _strip_common_top(name, *read_tar_gz(stream, limits=limits, wanted=wanted))
    raise InvalidInput(f"{source} is neither a folder nor a .tar.gz file", field="path")


def read_tar_gz(stream: IO[bytes], *, limits: ExportLimits = DEFAULT_LIMITS,
                wanted: Callable[[str], bool] = wanted_file) -> tuple[dict[str, bytes], list[str]]:
    """Stream a .tar.gz and keep the wanted members (bounded). Raises InvalidInput / PayloadTooLarge."""
    head = stream.read(2)
    if head != b"\x1f\x8b":
        raise InvalidInput("the export is not a .tar.gz file (no gzip header)", field="path")
    counted = _ExpansionGuard(gzip.GzipFile(fileobj=_Prefixed(head, stream)), limits.max_expanded_bytes)
    files: dict[str, bytes] = {}
    names: list[str] = []
    total = 0
    try:
        with tarfile.open(fileobj=counted, mode="r|") as archive:
            for count, member in enumerate(archive, start=1):
                if count > limits.max_members:
                    raise PayloadTooLarge(f"the export holds more than {limits.max_members} entries", field="path")
                name = _vetted_name(member, limits)
                if name is None or not member.isreg():
                    continue  # links, devices, directories and unsafe names are never read
                names.append(name)
                if not wanted(name):
                    continue
                if member.size > limits.max_file_bytes:
                    raise PayloadTooLarge(f"{name} is larger than {_size(limits.max_file_bytes)}", field=name)
                total += member.size
                if total > limits.max_total_read_bytes:
                    raise PayloadTooLarge("the export's metadata and metrics files are too large together",
                                          field="path")
                handle = archive.extractfile(member)
                files[name] = handle.read(limits.max_file_bytes + 1) if handle else b""
    except (tarfile.TarError, EOFError, OSError, zlib.error) as error:
        raise InvalidInput(f"the export archive is damaged: {error}", field="path") from None
    return files, names


def _read_folder(root: Path, limits: ExportLimits, wanted: Callable[[str], bool]) -> tuple[dict[str, bytes], list[str]]:
    files: dict[str, bytes] = {}
    names: list[str] = []
    total = 0
    for directory, subdirectories, filenames in os.walk(root, followlinks=False):
        relative_dir = Path(directory).relative_to(root)
        if len(relative_dir.parts) >= limits.max_depth:
            subdirectories.clear()
        for filename in sorted(filenames):
            path = Path(directory) / filename
            if path.is_symlink() or not path.is_file():
                continue
            name = (relative_dir / filename).as_posix()
            names.append(name)
            if len(names) > limits.max_members:
                raise PayloadTooLarge(f"the export holds more than {limits.max_members} files", field="path")
            if not wanted(name):
                continue
            size = path.stat().st_size
            if size > limits.max_file_bytes:
                raise PayloadTooLarge(f"{name} is larger than {_size(limits.max_file_bytes)}", field=name)
            total += size
            if total > limits.max_total_read_bytes:
                raise PayloadTooLarge("the export's metadata and metrics files are too large together", field="path")
            with path.open("rb") as handle:
                files[name] = handle.read(limits.max_file_bytes + 1)
    return files, names


def _strip_common_top(source_name: str, files: dict[str, bytes], names: list[str]) -> ExportFiles:
    """`my-model/ip/hyperparameters.json` and `ip/hyperparameters.json` are the same export."""
    tops = {name.split("/", 1)[0] for name in names}
    if len(tops) == 1 and all("/" in name for name in names):
        top = tops.pop()
        cut = len(top) + 1
        return ExportFiles(top, {name[cut:]: data for name, data in files.items()}, [name[cut:] for name in names])
    return ExportFiles(source_name, files, names)


def _size(count: int) -> str:
    return f"{count / MiB:g} MiB" if count >= MiB else f"{count} bytes"


def _vetted_name(member: tarfile.TarInfo, limits: ExportLimits) -> str | None:
    """The member's normalised name, or None when it must be skipped (refused, or the root folder)."""
    try:
        name = vet_member_name(member.name, max_length=512, max_depth=limits.max_depth)
        vet_member_type(member, name)
    except RefusedMember:
        return None
    return name


class _ExpansionGuard:
    """A read-only stream that refuses to hand out more than `limit` decompressed bytes."""

    def __init__(self, inner: IO[bytes], limit: int) -> None:
        self._inner = inner
        self._limit = limit
        self._seen = 0

    def read(self, size: int = -1) -> bytes:
        data = self._inner.read(size if size and size > 0 else 1 * MiB)
        self._seen += len(data)
        if self._seen > self._limit:
            raise PayloadTooLarge(f"the export expands to more than {_size(self._limit)}", field="path")
        return data


class _Prefixed:
    """Put back the bytes already read for the magic check."""

    def __init__(self, head: bytes, rest: IO[bytes]) -> None:
        self._head = head
        self._rest = rest

    def read(self, size: int = -1) -> bytes:
        if self._head:
            head, self._head = self._head, b""
            if size is None or size < 0:
                return head + self._rest.read()
            return head + self._rest.read(max(size - len(head), 0))
        return self._rest.read(size)
