"""Unpack a model archive on the car, trusting none of its member names.

The server validated the archive at upload and the car verified its md5 before calling this, so a bad archive here
means tampering or a bug; the extractor still re-checks every member (defence in depth): regular files only (no
links, devices, fifos), relative names without `..`, backslashes or NULs, bounded count and size. It writes into a
directory it is given (a fresh staging directory), never anywhere else.
"""
from __future__ import annotations

import tarfile
from pathlib import Path, PurePosixPath

MAX_MEMBERS = 64
MAX_TOTAL_BYTES = 512 * 1024 * 1024


class UnsafeArchive(ValueError):
    """The archive has a member the car refuses to write."""


def _safe_relative(name: str) -> PurePosixPath:
    if not name or "\\" in name or "\x00" in name or any(ord(c) < 32 for c in name):
        raise UnsafeArchive(f"member name {name!r} has forbidden characters")
    path = PurePosixPath(name)
    if path.is_absolute() or any(part == ".." for part in path.parts) or (path.parts and ":" in path.parts[0]):
        raise UnsafeArchive(f"member {name!r} points outside the model folder")
    parts = [p for p in path.parts if p not in ("", ".")]
    if not parts:
        raise UnsafeArchive(f"member name {name!r} is empty")
    return PurePosixPath(*parts)


def safe_extract(archive: Path, destination: Path) -> list[str]:
    """Extract regular files of a .tar.gz into `destination` (must exist and be empty); returns the member names."""
    destination = destination.resolve()
    written: list[str] = []
    total = 0
    try:
        with tarfile.open(archive, mode="r|gz") as stream:
            for member in stream:
                relative = _safe_relative(member.name)
                if member.isdir():
                    continue
                if not member.isreg():
                    raise UnsafeArchive(f"member {member.name!r} is not a regular file (links and devices refused)")
                if len(written) >= MAX_MEMBERS:
                    raise UnsafeArchive(f"more than {MAX_MEMBERS} files")
                total += member.size
                if total > MAX_TOTAL_BYTES:
                    raise UnsafeArchive(f"unpacks to more than {MAX_TOTAL_BYTES // (1024 * 1024)} MiB")
                target = destination.joinpath(*relative.parts)
                if destination not in target.resolve().parents:
                    raise UnsafeArchive(f"member {member.name!r} points outside the model folder")
                target.parent.mkdir(parents=True, exist_ok=True)
                source = stream.extractfile(member)
                if source is None:
                    raise UnsafeArchive(f"member {member.name!r} has no data")
                with open(target, "xb") as out:  # "x": a duplicate name cannot overwrite an earlier member
                    while piece := source.read(1 << 16):
                        out.write(piece)
                written.append(str(relative))
    except (tarfile.TarError, EOFError, OSError) as exc:
        if isinstance(exc, FileExistsError):
            raise UnsafeArchive(f"the archive names a file twice ({exc.filename})") from None
        raise UnsafeArchive(f"not a readable .tar.gz ({exc})") from None
    return written
