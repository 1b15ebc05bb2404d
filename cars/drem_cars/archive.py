"""Unpack a model archive on the car, trusting none of its member names.

The server validated the archive at upload and the car verified its md5 before calling this, so a bad archive here
means tampering or a bug; the extractor still re-checks every member (defence in depth) with the server's own rules
(drem_archive.member_names: regular files and folders only, no links, devices or fifos; relative names without `..`,
backslashes, drive letters, control or invisible characters), bounded count and size. It writes into a
directory it is given (a fresh staging directory), never anywhere else.
"""
from __future__ import annotations

import tarfile
from pathlib import Path, PurePosixPath

from drem_archive.member_names import RefusedMember, vet_member_name, vet_member_type

MAX_MEMBERS = 64
MAX_TOTAL_BYTES = 512 * 1024 * 1024


class UnsafeArchive(ValueError):
    """The archive has a member the car refuses to write."""


def _vetted(member: tarfile.TarInfo) -> PurePosixPath | None:
    """The member's relative path (None: a folder, written as its files are), by the one vetting every drem reader
    of archives uses (drem_archive.member_names)."""
    try:
        name = vet_member_name(member.name)
        vet_member_type(member, name)
    except RefusedMember as refused:
        raise UnsafeArchive(refused.reason) from None
    return None if member.isdir() or name is None else PurePosixPath(name)


def safe_extract(archive: Path, destination: Path) -> list[str]:
    """Extract regular files of a .tar.gz into `destination` (must exist and be empty); returns the member names."""
    destination = destination.resolve()
    written: list[str] = []
    total = 0
    try:
        with tarfile.open(archive, mode="r|gz") as stream:
            for member in stream:
                relative = _vetted(member)
                if relative is None:
                    continue
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
