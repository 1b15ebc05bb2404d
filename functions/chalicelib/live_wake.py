"""The writer wakes the live server: after a board or overlay write the app sends the event id, as one datagram, to
every live-server process's wake socket in `DREM_LIVE_WAKE_DIR` (`<dir>/<pid>.sock`, Unix datagram sockets; the
local stack sets the directory beside its state). The live server then re-reads that event's channels at once instead
of at its next storage poll, which stays as the fallback for anything a datagram misses.

Fire and forget: the send never blocks the writer (a full socket buffer or a live server that is gone only costs the
lap its fast path; a socket nobody listens on any more is removed). A datagram only makes the live server read what
is public anyway, and a channel re-reads at most once per wake window, so a forged one costs a read, nothing else.
On AWS the Lambda functions cannot reach the live tasks' sockets: there the live server polls (docs/deploy.md).
"""
from __future__ import annotations

import socket
from collections.abc import Callable
from pathlib import Path

SUFFIX = ".sock"
MAX_SOCKET_PATH = 107  # sun_path holds 108 bytes with the terminating NUL


def socket_path(directory: str | Path, pid: int) -> Path:
    return Path(directory) / f"{pid}{SUFFIX}"


class LiveWaker:
    def __init__(self, directory: str | Path) -> None:
        self._directory = Path(directory)
        self._socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._socket.setblocking(False)

    def __call__(self, event_id: str) -> None:
        data = event_id.encode()
        try:
            targets = [p for p in self._directory.iterdir() if p.name.endswith(SUFFIX)]
        except OSError:
            return  # no live server has started yet
        for target in targets:
            try:
                self._socket.sendto(data, str(target))
            except (ConnectionRefusedError, FileNotFoundError):
                target.unlink(missing_ok=True)  # its process is gone
            except OSError:
                pass  # buffer full or path too long: that live server's poll catches up


_WAKERS: dict[str, LiveWaker] = {}


def waker(directory: str) -> Callable[[str], None] | None:
    """The waker for `directory` (settings.live_wake_dir; one socket per process), or None when there is none."""
    if not directory:
        return None
    if directory not in _WAKERS:
        _WAKERS[directory] = LiveWaker(directory)
    return _WAKERS[directory]
