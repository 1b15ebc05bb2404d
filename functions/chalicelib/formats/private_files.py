"""Files the CLI writes that hold personal data or secrets (exports, import reports, temporary passwords): created new,
readable by their owner only, never through a file or link someone else put there first.

An export holds racers' e-mail addresses and an import's resume file their temporary passwords; organisers run these
in shared folders. `O_EXCL` (with `O_NOFOLLOW`) refuses a name that already exists, so a file or symlink planted by
another user never receives the data; 0600 files in 0700 folders keep other users of the machine out.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

PRIVATE_FILE = 0o600
PRIVATE_DIR = 0o700
_NEW = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


def write_new(path: Path, data: bytes, *, fsync: bool = False) -> None:
    """Create `path` (it must not exist) as a 0600 file holding `data`."""
    descriptor = os.open(path, _NEW, PRIVATE_FILE)
    try:
        os.fchmod(descriptor, PRIVATE_FILE)  # whatever the umask
        view = memoryview(data)
        while view:
            view = view[os.write(descriptor, view):]
        if fsync:
            os.fsync(descriptor)
    finally:
        os.close(descriptor)


def make_dir(path: Path) -> None:
    """Create `path` (and missing parents) as 0700 folders, or make an existing folder of ours 0700."""
    missing = [folder for folder in [path, *path.parents] if not folder.exists()]
    for folder in reversed(missing):
        folder.mkdir(mode=PRIVATE_DIR, exist_ok=True)
        if folder != path:
            folder.chmod(PRIVATE_DIR)  # mkdir's mode is cut by the umask
    path.mkdir(mode=PRIVATE_DIR, exist_ok=True)
    info = path.lstat()
    if not stat.S_ISDIR(info.st_mode):
        raise NotADirectoryError(f"{path} is not a folder")
    if info.st_uid == os.getuid():
        path.chmod(PRIVATE_DIR)


def read_own(path: Path) -> bytes | None:
    """The bytes of `path` if it is a regular file of this user that nobody else may write; None if it is missing.

    Raises PermissionError for a file someone else could have planted or changed (its content must not be trusted)."""
    try:
        descriptor = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    except FileNotFoundError:
        return None
    except OSError as exc:  # ELOOP: a symlink
        raise PermissionError(f"{path} is not a plain file of yours; remove it and run again") from exc
    with os.fdopen(descriptor, "rb") as handle:
        info = os.fstat(handle.fileno())
        if not stat.S_ISREG(info.st_mode) or info.st_uid != os.getuid() or info.st_mode & 0o077:
            raise PermissionError(f"{path} belongs to another user or others may read or change it; remove it and "
                                  "run again")
        return handle.read()
