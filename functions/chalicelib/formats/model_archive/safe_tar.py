"""Reading a `.tar.gz` without trusting a byte: streamed once, every byte counted, every member vetted and bounded.

Why the gzip layer is ours and tar runs in stream mode ("r|") rather than `tarfile.open(mode="r:gz")`: with "r:gz",
tarfile owns the decompressor, skips members by seeking (which inflates everything in between) and reads GNU
long-name / pax headers of any declared size straight into memory. Here every byte read is counted on both sides of the
decompressor, declared sizes are checked from each header before its data is touched, and meta headers have their
own small cap, so a gzip bomb is stopped after a few KiB instead of being inflated.

Member names and kinds go through the one vetting of `drem_archive.member_names`: a trick quarantines the
archive, an unusable name makes it NOT_VALID. Data after the tar end marker quarantines it too.
"""
from __future__ import annotations

import gzip
import hashlib
import os
import tarfile
import zlib
from collections.abc import Callable, Collection
from typing import IO, BinaryIO

from chalicelib.formats.model_archive.limits import ArchiveLimits, size_text
from chalicelib.formats.model_archive.report import ArchiveProblem, not_valid, quarantine
from chalicelib.formats.model_archive.streams import CountingReader, Prefixed, TailWindow
from drem_archive.member_names import HostileMember, RefusedMember, vet_member_name, vet_member_type

ArchiveSource = str | os.PathLike[str] | BinaryIO | IO[bytes]
OpenOutput = Callable[[str], IO[bytes]]  # vetted member name → where its bytes go (extraction)

_CHUNK = 1024 * 1024
_GZIP_MAGIC = b"\x1f\x8b"
_ZIP_MAGIC = b"PK\x03\x04"
_META_HEADER_TYPES = (tarfile.GNUTYPE_LONGNAME, tarfile.GNUTYPE_LONGLINK, tarfile.XHDTYPE, tarfile.XGLTYPE,
                      tarfile.SOLARIS_XHDTYPE)
# How much of the inflated stream is kept behind the reader: tarfile's stream mode reads ahead by at most one record
# (20 blocks), so the bytes after the end marker it already consumed are always inside this window.
_TAIL_WINDOW = 4 * tarfile.RECORDSIZE


class TarFacts:
    """What one pass over the archive learnt: counts, and per regular file its size and md5."""

    def __init__(self) -> None:
        self.member_count = 0
        self.total_size = 0
        self.md5: dict[str, str] = {}
        self.sizes: dict[str, int] = {}
        self.claimed_files: set[str] = set()  # case-folded
        self.claimed_folders: set[str] = set()  # case-folded
        self.kept: dict[str, bytes] = {}  # the bytes of the small members the caller asked to keep


class SafeTarReader:
    """One streaming pass; `keep` names small members (at most `limits.max_metadata_bytes`) whose bytes are kept."""

    def __init__(self, limits: ArchiveLimits, keep: Collection[str], open_output: OpenOutput | None = None) -> None:
        self._limits = limits
        self._keep = frozenset(keep)
        self._open_output = open_output
        self.facts = TarFacts()

    def read(self, source: ArchiveSource) -> TarFacts:
        """Raises ArchiveProblem at the first thing wrong (self.facts says how far it got)."""
        if isinstance(source, str | os.PathLike):
            size = os.stat(source).st_size
            if size > self._limits.max_compressed_bytes:
                raise not_valid(f"the archive is {size_text(size)}; uploads are limited to "
                                f"{size_text(self._limits.max_compressed_bytes)}")
            with open(source, "rb") as stream:
                self._read_stream(stream)
        else:
            self._read_stream(source)
        return self.facts

    def _read_stream(self, stream: IO[bytes]) -> None:
        limit = self._limits.max_compressed_bytes
        compressed = CountingReader(
            stream, limit, lambda: not_valid(f"the archive is larger than the {size_text(limit)} upload limit")
        )
        head = compressed.read(2)
        if head != _GZIP_MAGIC:
            raise not_valid(_not_gzip_reason(head + compressed.read(tarfile.BLOCKSIZE)))
        inflated_limit = self._limits.max_inflated_bytes
        inflated = CountingReader(
            gzip.GzipFile(fileobj=Prefixed(head, compressed), mode="rb"),
            inflated_limit,
            lambda: not_valid(
                f"the archive unpacks to more than {size_text(inflated_limit)} (limit "
                f"{size_text(self._limits.max_total_bytes)} of files); it looks like a compression bomb"
            ),
        )
        try:
            tail = TailWindow(inflated, _TAIL_WINDOW)
            with tarfile.open(fileobj=tail, mode="r|", tarinfo=_guarded_tarinfo(self._limits)) as archive:
                for member in archive:
                    self._take(archive, member)
                end_marker = archive.offset  # where tarfile met the first zero block
            _check_nothing_after_end(tail, end_marker)
        except ArchiveProblem:
            raise
        except EOFError:
            raise not_valid("the archive is truncated: the compressed data ends too early") from None
        except (gzip.BadGzipFile, zlib.error) as error:
            raise not_valid(f"the archive's gzip data is corrupt ({error})") from None
        except tarfile.TarError as error:
            raise not_valid(f"the archive does not contain a valid tar file ({error})") from None
        except (ValueError, UnicodeError, OverflowError) as error:  # malformed numbers/text inside tar headers
            raise not_valid(f"the archive's tar headers are malformed ({type(error).__name__})") from None

    def _take(self, archive: tarfile.TarFile, member: tarfile.TarInfo) -> None:
        facts = self.facts
        try:  # quarantine checks first: they matter most
            name = vet_member_name(member.name, max_length=self._limits.max_path_length)
            vet_member_type(member, name)
        except HostileMember as refused:
            raise quarantine(refused.reason) from None
        except RefusedMember as refused:
            raise not_valid(refused.reason) from None
        facts.member_count += 1
        if facts.member_count > self._limits.max_members:
            raise not_valid(f"the archive holds more than {self._limits.max_members} files and folders")
        if name is None or member.isdir():
            return
        self._check_sizes(member, name)
        self._claim(name)
        facts.total_size += member.size
        self._copy(archive, member, name)

    def _check_sizes(self, member: tarfile.TarInfo, name: str) -> None:
        limits = self._limits
        if member.size < 0:
            raise not_valid(f"{name!r} declares a negative size")
        if member.size > limits.max_member_bytes:
            raise not_valid(f"{name!r} is {size_text(member.size)}; a single file may be at most "
                            f"{size_text(limits.max_member_bytes)}")
        if self.facts.total_size + member.size > limits.max_total_bytes:
            raise not_valid(f"the archive's files add up to more than {size_text(limits.max_total_bytes)}")
        if name in self._keep and member.size > limits.max_metadata_bytes:
            raise not_valid(f"{name} is {size_text(member.size)}; it may be at most "
                            f"{size_text(limits.max_metadata_bytes)}")
        if getattr(member, "sparse", None):
            raise not_valid(f"{name!r} is a sparse file, which model archives do not use")

    def _claim(self, name: str) -> None:
        # Case-folded so that `Model.pb` and `model.pb` cannot shadow each other on a case-insensitive disk.
        facts = self.facts
        folded = name.casefold()
        if folded in facts.claimed_files:
            raise not_valid(f"the archive holds {name!r} more than once")
        parts = folded.split("/")
        folders = {"/".join(parts[:depth]) for depth in range(1, len(parts))}
        if folded in facts.claimed_folders or folders & facts.claimed_files:
            raise not_valid(f"{name!r} is used both as a file and as a folder")
        facts.claimed_files.add(folded)
        facts.claimed_folders |= folders

    def _copy(self, archive: tarfile.TarFile, member: tarfile.TarInfo, name: str) -> None:
        data = archive.extractfile(member)
        assert data is not None  # regular files always have data
        digest = hashlib.md5(usedforsecurity=False)  # DREM's identity of a model, not a security check
        keep = name in self._keep
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
            raise not_valid(f"the archive is truncated inside {name!r}") from None
        finally:
            if output:
                output.close()
        if read != member.size:
            raise not_valid(f"the archive is truncated inside {name!r}")
        self.facts.md5[name] = digest.hexdigest()
        self.facts.sizes[name] = read
        if keep:
            self.facts.kept[name] = b"".join(kept)


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
                raise not_valid(f"{self.name!r} is a sparse file, which model archives do not use")
            if self.type in _META_HEADER_TYPES:
                seen += 1
                if seen > most:
                    raise not_valid(f"the archive holds more than {most} tar extension headers")
                if self.size > limits.max_meta_header_bytes:
                    raise not_valid(
                        f"the archive holds a {size_text(self.size)} tar header; headers over "
                        f"{size_text(limits.max_meta_header_bytes)} are refused"
                    )
            return super()._proc_member(tarfile_)

    return GuardedTarInfo


def _check_nothing_after_end(tail: TailWindow, end_marker: int) -> None:
    """Every byte after the tar end marker must be zero padding, up to the end of the last gzip member.

    tarfile stops at the first zero block, but `tar --ignore-zeros`, bsdtar and naive extractors go on; a member
    after the marker, or a second gzip member (gzip readers concatenate them), would never have been checked.
    Reading to the end also makes a truncated or corrupt gzip noticed (the CRC sits last)."""
    already_read = tail.since(end_marker)
    if already_read is None:  # cannot happen with tarfile's read-ahead; refuse rather than guess
        raise not_valid("the archive's tar end marker could not be located")
    chunk = already_read
    while True:
        if chunk.strip(b"\x00"):
            raise quarantine(
                "the archive hides data after the tar end marker (a second archive or gzip member that other "
                "tools would unpack); re-create it with a single `tar -czf`"
            )
        chunk = tail.read(_CHUNK)
        if not chunk:
            return


def _not_gzip_reason(head: bytes) -> str:
    if not head:
        return "the file is empty; upload the model's .tar.gz"
    if head.startswith(_ZIP_MAGIC):
        return "this is a zip file; DeepRacer models are .tar.gz archives"
    if head[257:262] == b"ustar":
        return "this is an uncompressed .tar; DeepRacer models are gzip-compressed .tar.gz archives"
    return "the file is not gzip-compressed; upload the model's .tar.gz as downloaded from DeepRacer"
