"""The state dir's disk, said in words: full or read-only, and what to do about it.

One wording everywhere a disk problem bites (the storage server's refusals, which the app passes on as 507,
`drem status`, `drem up`): "drem's data disk is full at <path>: free space, then …".
"""
from __future__ import annotations

import errno
import os
from dataclasses import dataclass
from pathlib import Path

FULL = "full"
READ_ONLY = "read-only"
_FULL_ERRNOS = {errno.ENOSPC, errno.EDQUOT}
_READ_ONLY_ERRNOS = {errno.EROFS}
# Below this much free space the disk counts as full: a snapshot of a busy event's state is a few MB.
LOW_FREE_BYTES = 16 * 1024 * 1024


def problem_of(exc: BaseException) -> str | None:
    """FULL or READ_ONLY when `exc` is the disk refusing a write; None for anything else."""
    if isinstance(exc, OSError):
        if exc.errno in _FULL_ERRNOS:
            return FULL
        if exc.errno in _READ_ONLY_ERRNOS:
            return READ_ONLY
    return None


def sentence(problem: str, path: Path, then: str) -> str:
    """The one wording: what is wrong, where, what to do, and what happens next (`then`)."""
    where = Path(path).resolve()
    if problem == READ_ONLY:
        return (f"drem's data disk is read-only at {where}: make it writable again (remount it read-write, or check "
                f"the disk for errors), then {then}")
    return f"drem's data disk is full at {where}: free space on that disk, then {then}"


@dataclass(frozen=True)
class DiskState:
    path: Path
    free_bytes: int
    read_only: bool

    @property
    def problem(self) -> str | None:
        if self.read_only:
            return READ_ONLY
        if self.free_bytes < LOW_FREE_BYTES:
            return FULL
        return None


def disk_state(path: Path) -> DiskState:
    """What the filesystem holding `path` says about itself (statvfs: the space an ordinary user may still use and
    the read-only mount flag)."""
    stats = os.statvfs(path)
    return DiskState(Path(path), stats.f_bavail * stats.f_frsize, bool(stats.f_flag & os.ST_RDONLY))
