"""The writer wakes the live server: after a board or overlay write the app tells it the event id, and the live server
re-reads that event's channels at once instead of at its next storage poll, which stays as the fallback for anything
a wake-up misses. `waker(settings)` is the one owner of "wake the live server"; it picks the path:

- locally (`DREM_LIVE_WAKE_DIR`): one datagram to every live-server process's wake socket in that directory
  (`<dir>/<pid>.sock`, Unix datagram sockets; the local stack sets the directory beside its state), below;
- on AWS (`DREM_LIVE_WAKE_SECRET`): the Lambda functions cannot reach the live tasks (they run outside the VPC, the
  load balancer is internal), so they POST the event id to the public live origin's WAKE_PATH, through CloudFront, with
  the stage's wake secret (chalicelib.live_wake_http); the task that takes it relays it to the other live tasks.

Fire and forget: a datagram never blocks the writer (a full socket buffer or a live server that is gone only costs the
lap its fast path; a socket nobody listens on any more is removed), and the POST waits at most a short bound. A wake
only makes the live server read what is public anyway, and a channel re-reads at most once per wake window, so a
forged one costs a read, nothing else.
"""
from __future__ import annotations

import socket
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

if TYPE_CHECKING:
    from chalicelib.settings import Settings

SUFFIX = ".sock"
# The HTTP path (drem_live.wake_route takes it; the CDK app routes it and hands both sides the secret).
WAKE_PATH = "/live/wake"
WAKE_SECRET_ENV = "DREM_LIVE_WAKE_SECRET"
WAKE_SECRET_HEADER = "X-Drem-Wake-Secret"
MIN_WAKE_SECRET_CHARS = 16
MAX_WAKE_BODY_BYTES = 128  # an event id
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


_WAKERS: dict[tuple[str, str], Callable[[str], None]] = {}


def waker(settings: Settings) -> Callable[[str], None] | None:
    """The writer's wake-up for these settings (one per process), or None when the live server only polls: datagrams
    to `live_wake_dir` locally, else a POST to the public origin's WAKE_PATH when the stage has a wake secret."""
    if settings.live_wake_dir:
        key = ("dir", settings.live_wake_dir)
        if key not in _WAKERS:
            _WAKERS[key] = LiveWaker(settings.live_wake_dir)
        return _WAKERS[key]
    if settings.live_wake_secret:
        from chalicelib.live_wake_http import HttpWaker

        url = wake_url(settings.public_url)
        key = ("http", url)
        if key not in _WAKERS:
            _WAKERS[key] = HttpWaker(url, settings.live_wake_secret)
        return _WAKERS[key]
    return None


def wake_url(public_url: str) -> str:
    """The live pages are at the root of the public origin (CloudFront routes /live/* to them), whatever path the
    site's own pages live under."""
    parts = urlsplit(public_url)
    return f"{parts.scheme}://{parts.netloc}{WAKE_PATH}"
