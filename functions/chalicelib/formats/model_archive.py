"""Judge an uploaded model archive (`.tar.gz`) without trusting a byte of it.

An upload is hostile input. `inspect_archive` streams the archive once, entirely in memory, and never extracts:

* QUARANTINED: anything that could write outside a sandbox if extracted (absolute paths, `..`, links, device files,
  fifos, NUL/backslash/drive-letter tricks, control, bidi-override and other invisible format characters in names),
  and any data hidden after the tar end marker (a later gzip member or tar members that `tar -i`, `bsdtar` or a
  careless extractor would still unpack).
* NOT_VALID: broken or unusable, with a reason a racer can act on (not gzip, truncated, not tar, too big, too many
  members, bad or missing `model_metadata.json`, no model file, duplicate names).
* AVAILABLE: the facts drem keeps about the model (kind, md5 of the model file and of the metadata, sensors, ...).

Why the gzip layer is ours and tar runs in stream mode ("r|") rather than `tarfile.open(mode="r:gz")`: with "r:gz",
tarfile owns the decompressor, skips members by seeking (which inflates everything in between) and reads GNU
long-name / pax headers of any declared size straight into memory. Here every byte read is counted on both sides of the
decompressor, declared sizes are checked from each header before its data is touched, and meta headers have their
own small cap, so a gzip bomb is stopped after a few KiB instead of being inflated.

`safe_extract` runs the very same scan and writes regular files (and nothing else) into a fresh temporary directory.
"""
from __future__ import annotations

import gzip
import hashlib
import io
import os
import re
import shutil
import tarfile
import tempfile
import unicodedata
import zlib
from collections import deque
from collections.abc import Callable
from enum import StrEnum
from pathlib import Path
from typing import IO, BinaryIO, Literal

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.domain.errors import InvalidInput
from chalicelib.formats.model_metadata import (ModelMetadata, ModelMetadataError, check_for_stock_car,
                                              parse_model_metadata_json)

KiB = 1024
MiB = 1024 * KiB

METADATA_MEMBER = "model_metadata.json"
# DROA (deepracer-on-aws) also accepts metadata under agent/; we do too, but only when the root copy is absent.
METADATA_FALLBACK_MEMBER = "agent/model_metadata.json"
TENSORFLOW_MEMBERS = ("agent/model.pb", "model.pb")  # console layout first, DROA's flat layout second
ONNX_MEMBER = "model.onnx"

MODEL_NAME_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,64}")
ARCHIVE_SUFFIX = ".tar.gz"

_CHUNK = 1 * MiB
_GZIP_MAGIC = b"\x1f\x8b"
_ZIP_MAGIC = b"PK\x03\x04"
_META_HEADER_TYPES = (tarfile.GNUTYPE_LONGNAME, tarfile.GNUTYPE_LONGLINK, tarfile.XHDTYPE, tarfile.XGLTYPE,
                      tarfile.SOLARIS_XHDTYPE)
_CONTROL_CHARACTERS = re.compile(r"[\x00-\x1f\x7f]")
# Unicode categories a file name never needs and a reviewer cannot see: C1 controls (Cc), format characters such as
# the bidi overrides U+202E/U+2066-2069 and zero-width joiners (Cf, the "Trojan Source" trick: `model\u202egnp.pb`
# shows as `modelbp.png`), and line/paragraph separators (Zl, Zp).
_INVISIBLE_CATEGORIES = frozenset({"Cc", "Cf", "Zl", "Zp"})
# How much of the inflated stream is kept behind the reader: tarfile's stream mode reads ahead by at most one record
# (20 blocks), so the bytes after the end marker it already consumed are always inside this window.
_TAIL_WINDOW = 4 * tarfile.RECORDSIZE


class ArchiveStatus(StrEnum):
    """The verdict; the values are DREM's model status names."""

    AVAILABLE = "AVAILABLE"
    NOT_VALID = "NOT_VALID"
    QUARANTINED = "QUARANTINED"


ModelKind = Literal["tensorflow", "onnx"]


class ArchiveLimits(BaseModel):
    model_config = ConfigDict(frozen=True)

    max_compressed_bytes: int = Field(default=128 * MiB, gt=0)
    max_total_bytes: int = Field(default=256 * MiB, gt=0, description="sum of all members, uncompressed")
    max_member_bytes: int = Field(default=128 * MiB, gt=0)
    max_members: int = Field(default=64, gt=0)
    max_metadata_bytes: int = Field(default=64 * KiB, gt=0)
    max_meta_header_bytes: int = Field(default=16 * KiB, gt=0, description="GNU long-name and pax headers")
    max_path_length: int = Field(default=255, gt=0)

    @property
    def max_inflated_bytes(self) -> int:
        """Everything the decompressor may produce: member data plus headers, padding and the tar end record."""
        per_member_overhead = self.max_meta_header_bytes + 3 * tarfile.BLOCKSIZE
        return self.max_total_bytes + self.max_members * per_member_overhead + 2 * tarfile.RECORDSIZE


DEFAULT_LIMITS = ArchiveLimits()


class ArchiveReport(BaseModel):
    status: ArchiveStatus
    reason: str | None = None
    model_kind: ModelKind | None = None
    model_member: str | None = None
    model_md5: str | None = None
    metadata_md5: str | None = None
    sensor: list[str] = Field(default_factory=list)
    action_space_type: str | None = None
    training_algorithm: str | None = None
    metadata: ModelMetadata | None = None
    member_count: int = 0
    total_size: int = 0

    @property
    def available(self) -> bool:
        return self.status is ArchiveStatus.AVAILABLE


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


class InvalidModelName(InvalidInput):
    pass


class ArchiveRejected(InvalidInput):
    """`safe_extract` refused an archive; `report` says why (QUARANTINED or NOT_VALID)."""

    def __init__(self, report: ArchiveReport) -> None:
        super().__init__(report.reason or "the model archive was rejected", field="archive")
        self.report = report


ArchiveSource = str | os.PathLike[str] | BinaryIO | IO[bytes]


def validate_model_name(name: str) -> str:
    """A model name is 1-64 letters, digits, `-` or `_` (it becomes an S3 key part and a folder on the car)."""
    if not isinstance(name, str) or not MODEL_NAME_PATTERN.fullmatch(name):
        shown = repr(name[:70]) if isinstance(name, str) else type(name).__name__
        raise InvalidModelName(
            f"model name {shown} is not allowed: use 1-64 letters, digits, '-' or '_' (no spaces, dots or slashes)",
            field="name",
        )
    return name


def model_name_from_filename(filename: str) -> str:
    """`My-model_3.tar.gz` -> `My-model_3` (DREM's upload rule: `^[A-Za-z0-9_-]+\\.tar\\.gz$`)."""
    if not isinstance(filename, str) or not filename.endswith(ARCHIVE_SUFFIX):
        raise InvalidModelName("a model upload must be a .tar.gz file", field="file")
    return validate_model_name(filename[: -len(ARCHIVE_SUFFIX)])


def inspect_archive(source: ArchiveSource, *, limits: ArchiveLimits = DEFAULT_LIMITS) -> ArchiveReport:
    """Stream the archive once and return its verdict. Never raises for bad archive content (a path that does not
    exist is the caller's mistake and raises FileNotFoundError)."""
    return _Scanner(limits).run(source)


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
        report = _Scanner(limits, open_output=_SandboxWriter(sandbox)).run(source)
    except BaseException:
        shutil.rmtree(sandbox, ignore_errors=True)
        raise
    if not report.available:
        shutil.rmtree(sandbox, ignore_errors=True)
        raise ArchiveRejected(report)
    return ExtractedArchive(root=sandbox, report=report)


class _Problem(Exception):
    def __init__(self, status: ArchiveStatus, reason: str) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason


def _quarantine(reason: str) -> _Problem:
    return _Problem(ArchiveStatus.QUARANTINED, reason)


def _not_valid(reason: str) -> _Problem:
    return _Problem(ArchiveStatus.NOT_VALID, reason)


def _size(count: int) -> str:
    if count >= MiB:
        return f"{count / MiB:.1f} MiB"
    if count >= KiB:
        return f"{count / KiB:.1f} KiB"
    return f"{count} bytes"


class _CountingReader(io.RawIOBase):
    """Passes reads through and raises `_Problem` once more than `limit` bytes went by."""

    def __init__(self, inner: IO[bytes], limit: int, problem: Callable[[], _Problem]) -> None:
        self._inner = inner
        self._limit = limit
        self._problem = problem
        self.count = 0

    def readable(self) -> bool:
        return True

    def read(self, size: int = -1) -> bytes:
        # Never let an unbounded read through: it is what a bomb relies on.
        wanted = self._limit + 1 - self.count if size is None or size < 0 else size
        data = self._inner.read(max(0, min(wanted, self._limit + 1 - self.count)))
        self.count += len(data)
        if self.count > self._limit:
            raise self._problem()
        return data

    def readinto(self, buffer) -> int:  # type: ignore[override]
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)


def _guarded_tarinfo(limits: ArchiveLimits) -> type[tarfile.TarInfo]:
    """A TarInfo that vets GNU long-name, pax and sparse headers before tarfile reads them into memory.

    These headers are not members (tarfile folds them into the next one), so neither the member count nor the
    declared-size checks would see them; a bomb could hide in one, or in thousands of small global headers.
    """
    seen = 0
    most = 2 * limits.max_members + 4  # a pax and a long-name header per member, plus a few global ones

    class GuardedTarInfo(tarfile.TarInfo):
        def _proc_member(self, tarfile_):  # noqa: ANN001 - tarfile's private hook, stable since Python 3.0
            nonlocal seen
            if self.type == tarfile.GNUTYPE_SPARSE:
                raise _not_valid(f"{self.name!r} is a sparse file, which model archives do not use")
            if self.type in _META_HEADER_TYPES:
                seen += 1
                if seen > most:
                    raise _not_valid(f"the archive holds more than {most} tar extension headers")
                if self.size > limits.max_meta_header_bytes:
                    raise _not_valid(
                        f"the archive holds a {_size(self.size)} tar header; headers over "
                        f"{_size(limits.max_meta_header_bytes)} are refused"
                    )
            return super()._proc_member(tarfile_)

    return GuardedTarInfo


class _SandboxWriter:
    """Creates files for already-vetted member names below `root`, refusing to follow or replace anything."""

    def __init__(self, root: Path) -> None:
        self._root = root

    def __call__(self, name: str) -> IO[bytes]:
        target = self._root.joinpath(*name.split("/"))
        if not target.resolve().is_relative_to(self._root):  # second line of defence; the scanner already checked
            raise _quarantine(f"member {name!r} would be written outside the sandbox")
        directory = self._root
        for part in name.split("/")[:-1]:
            directory = directory / part
            try:
                directory.mkdir(mode=0o755)
            except FileExistsError:
                if directory.is_symlink() or not directory.is_dir():
                    raise _not_valid(f"member {name!r} needs {part!r} to be a folder, but it is a file") from None
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
        try:
            descriptor = os.open(target, flags, 0o644)
        except FileExistsError:
            raise _not_valid(f"the archive holds {name!r} twice") from None
        return os.fdopen(descriptor, "wb")


class _Facts:
    def __init__(self) -> None:
        self.member_count = 0
        self.total_size = 0
        self.md5: dict[str, str] = {}
        self.sizes: dict[str, int] = {}
        self.claimed_files: set[str] = set()  # case-folded
        self.claimed_folders: set[str] = set()  # case-folded
        self.metadata_bytes: dict[str, bytes] = {}


class _Scanner:
    def __init__(self, limits: ArchiveLimits, open_output: Callable[[str], IO[bytes]] | None = None) -> None:
        self._limits = limits
        self._open_output = open_output
        self._facts = _Facts()

    def run(self, source: ArchiveSource) -> ArchiveReport:
        try:
            self._scan(source)
            return self._judge()
        except _Problem as problem:
            return self._report(problem.status, problem.reason)

    def _report(self, status: ArchiveStatus, reason: str | None, **facts) -> ArchiveReport:
        return ArchiveReport(
            status=status,
            reason=reason,
            member_count=self._facts.member_count,
            total_size=self._facts.total_size,
            **facts,
        )

    # -- streaming -------------------------------------------------------------------------------------------------

    def _scan(self, source: ArchiveSource) -> None:
        if isinstance(source, str | os.PathLike):
            size = os.stat(source).st_size
            self._check_compressed_size(size)
            with open(source, "rb") as stream:
                self._scan_stream(stream)
        else:
            self._scan_stream(source)

    def _check_compressed_size(self, size: int) -> None:
        if size > self._limits.max_compressed_bytes:
            raise _not_valid(
                f"the archive is {_size(size)}; uploads are limited to {_size(self._limits.max_compressed_bytes)}"
            )

    def _scan_stream(self, stream: IO[bytes]) -> None:
        limit = self._limits.max_compressed_bytes
        compressed = _CountingReader(
            stream, limit, lambda: _not_valid(f"the archive is larger than the {_size(limit)} upload limit")
        )
        head = compressed.read(2)
        if head != _GZIP_MAGIC:
            raise _not_valid(_not_gzip_reason(head + compressed.read(tarfile.BLOCKSIZE)))
        inflated_limit = self._limits.max_inflated_bytes
        inflated = _CountingReader(
            gzip.GzipFile(fileobj=_Prefixed(head, compressed), mode="rb"),
            inflated_limit,
            lambda: _not_valid(
                f"the archive unpacks to more than {_size(inflated_limit)} (limit "
                f"{_size(self._limits.max_total_bytes)} of files); it looks like a compression bomb"
            ),
        )
        try:
            tail = _TailWindow(inflated, _TAIL_WINDOW)
            with tarfile.open(fileobj=tail, mode="r|", tarinfo=_guarded_tarinfo(self._limits)) as archive:
                for member in archive:
                    self._take(archive, member)
                end_marker = archive.offset  # where tarfile met the first zero block
            self._check_nothing_after_end(tail, end_marker)
        except _Problem:
            raise
        except EOFError:
            raise _not_valid("the archive is truncated: the compressed data ends too early") from None
        except (gzip.BadGzipFile, zlib.error) as error:
            raise _not_valid(f"the archive's gzip data is corrupt ({error})") from None
        except tarfile.TarError as error:
            raise _not_valid(f"the archive does not contain a valid tar file ({error})") from None
        except (ValueError, UnicodeError, OverflowError) as error:  # malformed numbers/text inside tar headers
            raise _not_valid(f"the archive's tar headers are malformed ({type(error).__name__})") from None

    @staticmethod
    def _check_nothing_after_end(tail: _TailWindow, end_marker: int) -> None:
        """Every byte after the tar end marker must be zero padding, up to the end of the last gzip member.

        tarfile stops at the first zero block, but `tar --ignore-zeros`, bsdtar and naive extractors go on; a member
        after the marker, or a second gzip member (gzip readers concatenate them), would never have been checked.
        Reading to the end also makes a truncated or corrupt gzip noticed (the CRC sits last)."""
        already_read = tail.since(end_marker)
        if already_read is None:  # cannot happen with tarfile's read-ahead; refuse rather than guess
            raise _not_valid("the archive's tar end marker could not be located")
        chunk = already_read
        while True:
            if chunk.strip(b"\x00"):
                raise _quarantine(
                    "the archive hides data after the tar end marker (a second archive or gzip member that other "
                    "tools would unpack); re-create it with a single `tar -czf`"
                )
            chunk = tail.read(_CHUNK)
            if not chunk:
                return

    def _take(self, archive: tarfile.TarFile, member: tarfile.TarInfo) -> None:
        facts = self._facts
        name = _vetted_name(member.name, self._limits)  # quarantine checks first: they matter most
        _vet_type(member, name)
        facts.member_count += 1
        if facts.member_count > self._limits.max_members:
            raise _not_valid(f"the archive holds more than {self._limits.max_members} files and folders")
        if name is None or member.isdir():
            return
        self._check_sizes(member, name)
        self._claim(name)
        facts.total_size += member.size
        self._copy(archive, member, name)

    def _check_sizes(self, member: tarfile.TarInfo, name: str) -> None:
        limits = self._limits
        if member.size < 0:
            raise _not_valid(f"{name!r} declares a negative size")
        if member.size > limits.max_member_bytes:
            raise _not_valid(f"{name!r} is {_size(member.size)}; a single file may be at most "
                             f"{_size(limits.max_member_bytes)}")
        if self._facts.total_size + member.size > limits.max_total_bytes:
            raise _not_valid(f"the archive's files add up to more than {_size(limits.max_total_bytes)}")
        if name in (METADATA_MEMBER, METADATA_FALLBACK_MEMBER) and member.size > limits.max_metadata_bytes:
            raise _not_valid(f"{name} is {_size(member.size)}; it may be at most {_size(limits.max_metadata_bytes)}")
        if getattr(member, "sparse", None):
            raise _not_valid(f"{name!r} is a sparse file, which model archives do not use")

    def _claim(self, name: str) -> None:
        # Case-folded so that `Model.pb` and `model.pb` cannot shadow each other on a case-insensitive disk.
        facts = self._facts
        folded = name.casefold()
        if folded in facts.claimed_files:
            raise _not_valid(f"the archive holds {name!r} more than once")
        parts = folded.split("/")
        folders = {"/".join(parts[:depth]) for depth in range(1, len(parts))}
        if folded in facts.claimed_folders or folders & facts.claimed_files:
            raise _not_valid(f"{name!r} is used both as a file and as a folder")
        facts.claimed_files.add(folded)
        facts.claimed_folders |= folders

    def _copy(self, archive: tarfile.TarFile, member: tarfile.TarInfo, name: str) -> None:
        data = archive.extractfile(member)
        assert data is not None  # regular files always have data
        digest = hashlib.md5(usedforsecurity=False)  # DREM's identity of a model, not a security check
        keep = name in (METADATA_MEMBER, METADATA_FALLBACK_MEMBER)
        kept: list[bytes] = []
        output = self._open_output(name) if self._open_output else None
        read = 0
        try:
            while read < member.size:
                chunk = data.read(min(_CHUNK, member.size - read))
                if not chunk:
                    break
                read += len(chunk)
                digest.update(chunk)
                if keep:
                    kept.append(chunk)
                if output:
                    output.write(chunk)
        except tarfile.ReadError:
            raise _not_valid(f"the archive is truncated inside {name!r}") from None
        finally:
            if output:
                output.close()
        if read != member.size:
            raise _not_valid(f"the archive is truncated inside {name!r}")
        self._facts.md5[name] = digest.hexdigest()
        self._facts.sizes[name] = read
        if keep:
            self._facts.metadata_bytes[name] = b"".join(kept)

    # -- judging ---------------------------------------------------------------------------------------------------

    def _judge(self) -> ArchiveReport:
        facts = self._facts
        metadata_member = next((m for m in (METADATA_MEMBER, METADATA_FALLBACK_MEMBER) if m in facts.metadata_bytes),
                               None)
        if metadata_member is None:
            raise _not_valid(f"the archive has no {METADATA_MEMBER} at its top level")
        try:
            metadata = parse_model_metadata_json(facts.metadata_bytes[metadata_member])
        except ModelMetadataError as error:
            raise _not_valid(error.message) from None
        model_kind, model_member = self._model_file(metadata)
        if any(m in facts.sizes for m in TENSORFLOW_MEMBERS):  # a .pb is for stock cars: judge as the car will
            try:
                check_for_stock_car(metadata)
            except ModelMetadataError as error:
                raise _not_valid(error.message) from None
        return self._report(
            ArchiveStatus.AVAILABLE,
            None,
            model_kind=model_kind,
            model_member=model_member,
            model_md5=facts.md5[model_member],
            metadata_md5=facts.md5[metadata_member],
            sensor=list(metadata.sensor),
            action_space_type=metadata.action_space_type.value,
            training_algorithm=metadata.training_origin,
            metadata=metadata,
        )

    def _model_file(self, metadata: ModelMetadata) -> tuple[ModelKind, str]:
        sizes = self._facts.sizes
        tensorflow = next((member for member in TENSORFLOW_MEMBERS if member in sizes), None)
        onnx = ONNX_MEMBER if ONNX_MEMBER in sizes else None
        # drem's own exports carry the same network twice: model.onnx (simulator, drem cars) and agent/model.pb
        # (stock cars), and say so in their metadata. Any other archive with both is ambiguous.
        drem_block = getattr(metadata, "drem", None)
        dual = isinstance(drem_block, dict) and drem_block.get("car_model_file") == tensorflow
        if tensorflow and onnx and not dual:
            raise _not_valid(f"the archive holds both {onnx} and {tensorflow}; upload one model per archive")
        if not tensorflow and not onnx:
            raise _not_valid("the archive has no model file: expected agent/model.pb (DeepRacer console) or "
                             "model.onnx (drem)")
        member = onnx or tensorflow
        assert member is not None
        if sizes[member] == 0:
            raise _not_valid(f"the model file {member} is empty")
        return ("onnx" if onnx else "tensorflow"), member


class _TailWindow(io.RawIOBase):
    """Passes reads through, counting the position and keeping the last `window` bytes read, so the bytes tarfile
    read ahead past its end marker can be checked too."""

    def __init__(self, inner: IO[bytes], window: int) -> None:
        self._inner = inner
        self._window = window
        self._kept: deque[bytes] = deque()
        self._kept_bytes = 0
        self.position = 0

    def readable(self) -> bool:
        return True

    def read(self, size: int = -1) -> bytes:
        data = self._inner.read(size)
        self.position += len(data)
        self._kept.append(data)
        self._kept_bytes += len(data)
        while self._kept and self._kept_bytes - len(self._kept[0]) >= self._window:
            self._kept_bytes -= len(self._kept.popleft())
        return data

    def readinto(self, buffer) -> int:  # type: ignore[override]
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)

    def since(self, offset: int) -> bytes | None:
        """The bytes read from `offset` up to the current position, or None if they are no longer kept."""
        start = self.position - self._kept_bytes
        if offset < start or offset > self.position:
            return None
        return b"".join(self._kept)[offset - start:]


class _Prefixed(io.RawIOBase):
    """Puts back the magic bytes we peeked at, for sources that cannot seek."""

    def __init__(self, prefix: bytes, rest: IO[bytes]) -> None:
        self._prefix = prefix
        self._rest = rest

    def readable(self) -> bool:
        return True

    def read(self, size: int = -1) -> bytes:
        if self._prefix:
            taken = self._prefix if size is None or size < 0 else self._prefix[:size]
            self._prefix = self._prefix[len(taken):]
            return taken
        return self._rest.read(size)

    def readinto(self, buffer) -> int:  # type: ignore[override]
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)


def _not_gzip_reason(head: bytes) -> str:
    if not head:
        return "the file is empty; upload the model's .tar.gz"
    if head.startswith(_ZIP_MAGIC):
        return "this is a zip file; DeepRacer models are .tar.gz archives"
    if head[257:262] == b"ustar":
        return "this is an uncompressed .tar; DeepRacer models are gzip-compressed .tar.gz archives"
    return "the file is not gzip-compressed; upload the model's .tar.gz as downloaded from DeepRacer"


def _vetted_name(raw: str, limits: ArchiveLimits) -> str | None:
    """The normalised member path, or None for the archive's own root folder (`.` / `./`)."""
    if "\x00" in raw:
        raise _quarantine(f"member name {raw!r} contains a NUL byte (tools disagree on where such a name ends)")
    if _CONTROL_CHARACTERS.search(raw):
        raise _quarantine(f"member name {raw!r} contains control characters")
    invisible = next((char for char in raw if unicodedata.category(char) in _INVISIBLE_CATEGORIES), None)
    if invisible is not None:
        raise _quarantine(
            f"member name {raw!r} contains the invisible or bidi-override character U+{ord(invisible):04X} "
            f"({unicodedata.name(invisible, 'unnamed')}), which makes a name display as something it is not"
        )
    try:
        raw.encode("utf-8")
    except UnicodeEncodeError:
        raise _quarantine(f"member name {raw!r} is not valid UTF-8") from None
    if "\\" in raw:
        raise _quarantine(f"member name {raw!r} contains a backslash (a Windows path trick)")
    if raw.startswith("/"):
        raise _quarantine(f"member {raw!r} has an absolute path")
    if ":" in raw:
        raise _quarantine(f"member name {raw!r} contains a drive letter or ':'")
    parts = raw.split("/")
    if ".." in parts:
        raise _quarantine(f"member {raw!r} climbs out of the archive with '..'")
    while parts and parts[0] == ".":
        parts = parts[1:]  # `tar -C dir .` writes ./model_metadata.json
    if parts and parts[-1] == "":
        parts = parts[:-1]  # folder written as `agent/`
    if not parts:
        return None
    if any(part in ("", ".") for part in parts):
        raise _not_valid(f"member name {raw!r} has empty or '.' path parts")
    name = "/".join(parts)
    if len(name) > limits.max_path_length:
        raise _not_valid(f"member name {name[:60]!r}... is longer than {limits.max_path_length} characters")
    return name


def _vet_type(member: tarfile.TarInfo, name: str | None) -> None:
    shown = name or member.name
    if member.issym():
        raise _quarantine(f"member {shown!r} is a symbolic link (to {member.linkname!r})")
    if member.islnk():
        raise _quarantine(f"member {shown!r} is a hard link (to {member.linkname!r})")
    if member.ischr() or member.isblk():
        raise _quarantine(f"member {shown!r} is a device file")
    if member.isfifo():
        raise _quarantine(f"member {shown!r} is a named pipe (fifo)")
    if not (member.isreg() or member.isdir()):
        raise _quarantine(f"member {shown!r} has an unsupported type {member.type!r}")
    if name is None and not member.isdir():
        raise _not_valid(f"member {member.name!r} is a file without a name")


__all__ = [
    "ArchiveLimits",
    "ArchiveRejected",
    "ArchiveReport",
    "ArchiveStatus",
    "DEFAULT_LIMITS",
    "ExtractedArchive",
    "InvalidModelName",
    "ModelKind",
    "inspect_archive",
    "model_name_from_filename",
    "safe_extract",
    "validate_model_name",
]
