"""Vetting the names and kinds of files inside hostile input: tar members and the files of an export folder.

The one set of rules for every reader of archives and export folders (model uploads, league exports, event
exports). A name is refused if extracting it anywhere could write outside the target folder or make it display as
something it is not: NUL, control, bidi-override and other invisible format characters, names that are not valid
UTF-8, backslashes, absolute paths, drive letters and '..' parts. A ':' elsewhere in a name is harmless on the
systems drem reads and writes on (Linux, macOS) and real exports need it: DeepRacer-on-AWS names every log and metrics
file after an ISO-8601 time (`2026-03-07T17:52:00.898Z-…-simulation.log`). A member is refused if it is anything but
a regular file or a folder (links, device files, fifos). Each caller decides what a refusal means: the model
validator quarantines the upload, the league reader skips the member, the event import refuses the folder.
"""
from __future__ import annotations

import os
import re
import stat
import tarfile
import unicodedata
from pathlib import Path

_CONTROL_CHARACTERS = re.compile(r"[\x00-\x1f\x7f]")
# `C:` at the start of a path part is a Windows drive (`C:/x`, `a/C:x` on Windows extraction tools): refused.
_DRIVE_LETTER = re.compile(r"(^|/)[A-Za-z]:")
# Unicode categories a file name never needs and a reviewer cannot see: C1 controls (Cc), format characters such as
# the bidi overrides U+202E/U+2066-2069 and zero-width joiners (Cf, the "Trojan Source" trick: `model\u202egnp.pb`
# shows as `modelbp.png`), and line/paragraph separators (Zl, Zp).
_INVISIBLE_CATEGORIES = frozenset({"Cc", "Cf", "Zl", "Zp"})
DEFAULT_MAX_NAME_LENGTH = 255


class RefusedMember(ValueError):
    """A member (or folder file) that must never be read or written; the message is a sentence for the user."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class HostileMember(RefusedMember):
    """A trick: the name or kind could escape a sandbox or disguise itself (quarantine-worthy)."""


class MalformedMember(RefusedMember):
    """Not a trick, but unusable: empty or '.' path parts, too long or too deep."""


def vet_member_name(raw: str, *, max_length: int = DEFAULT_MAX_NAME_LENGTH, max_depth: int | None = None) -> str | None:
    """The normalised member path (`./a/b/` → `a/b`), or None for the archive's own root folder (`.` / `./`).

    Raises HostileMember or MalformedMember (both RefusedMember)."""
    if "\x00" in raw:
        raise HostileMember(f"member name {raw!r} contains a NUL byte (tools disagree on where such a name ends)")
    if _CONTROL_CHARACTERS.search(raw):
        raise HostileMember(f"member name {raw!r} contains control characters")
    invisible = next((char for char in raw if unicodedata.category(char) in _INVISIBLE_CATEGORIES), None)
    if invisible is not None:
        raise HostileMember(
            f"member name {raw!r} contains the invisible or bidi-override character U+{ord(invisible):04X} "
            f"({unicodedata.name(invisible, 'unnamed')}), which makes a name display as something it is not"
        )
    try:
        raw.encode("utf-8")
    except UnicodeEncodeError:
        raise HostileMember(f"member name {raw!r} is not valid UTF-8") from None
    if "\\" in raw:
        raise HostileMember(f"member name {raw!r} contains a backslash (a Windows path trick)")
    if raw.startswith("/"):
        raise HostileMember(f"member {raw!r} has an absolute path")
    if _DRIVE_LETTER.search(raw):
        raise HostileMember(f"member name {raw!r} starts a path part with a drive letter")
    parts = raw.split("/")
    if ".." in parts:
        raise HostileMember(f"member {raw!r} climbs out of the archive with '..'")
    while parts and parts[0] == ".":
        parts = parts[1:]  # `tar -C dir .` writes ./model_metadata.json
    if parts and parts[-1] == "":
        parts = parts[:-1]  # folder written as `agent/`
    if not parts:
        return None
    if any(part in ("", ".") for part in parts):
        raise MalformedMember(f"member name {raw!r} has empty or '.' path parts")
    name = "/".join(parts)
    if len(name) > max_length:
        raise MalformedMember(f"member name {name[:60]!r}... is longer than {max_length} characters")
    if max_depth is not None and len(parts) > max_depth:
        raise MalformedMember(f"member name {name[:60]!r} is nested more than {max_depth} folders deep")
    return name


def vet_member_type(member: tarfile.TarInfo, name: str | None) -> None:
    """Only regular files and folders pass; `name` is the vetted name (None: the root folder)."""
    shown = name or member.name
    if member.issym():
        raise HostileMember(f"member {shown!r} is a symbolic link (to {member.linkname!r})")
    if member.islnk():
        raise HostileMember(f"member {shown!r} is a hard link (to {member.linkname!r})")
    if member.ischr() or member.isblk():
        raise HostileMember(f"member {shown!r} is a device file")
    if member.isfifo():
        raise HostileMember(f"member {shown!r} is a named pipe (fifo)")
    if not (member.isreg() or member.isdir()):
        raise HostileMember(f"member {shown!r} has an unsupported type {member.type!r}")
    if name is None and not member.isdir():
        raise MalformedMember(f"member {member.name!r} is a file without a name")


def vet_folder_file(root: Path, raw: str) -> Path:
    """The path of the regular file `raw` (a relative name, vetted as a member name) below `root`.

    Every part is checked without following links, so a symbolic link (to /etc/passwd, or a folder elsewhere) or a
    device in an export folder is refused rather than read. Raises RefusedMember; FileNotFoundError if missing."""
    name = vet_member_name(raw)
    if name is None:
        raise MalformedMember(f"member name {raw!r} names the folder itself, not a file")
    path = root
    parts = name.split("/")
    for depth, part in enumerate(parts, start=1):
        path = path / part
        mode = os.lstat(path).st_mode
        if stat.S_ISLNK(mode):
            raise HostileMember(f"{'/'.join(parts[:depth])!r} is a symbolic link; export folders hold plain files")
        is_last = depth == len(parts)
        if is_last and not stat.S_ISREG(mode) or not is_last and not stat.S_ISDIR(mode):
            raise HostileMember(f"{'/'.join(parts[:depth])!r} is not a plain "
                                f"{'file' if is_last else 'folder'} (a device, fifo or socket is never read)")
    return path
