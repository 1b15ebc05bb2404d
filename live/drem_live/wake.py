"""The live server's wake socket: the app's writer (chalicelib.live_wake) sends an event id as one datagram after each
board or overlay write, and every channel of that event reads storage at once instead of at its next poll.

One Unix datagram socket per process, `<DREM_LIVE_WAKE_DIR>/<pid>.sock`, created owner-only and removed when the
process stops. A datagram that is not an event id is ignored; one that is only makes the channels re-read public data
(at most once per MIN_READ_GAP_S each), so a forged one costs a read.
"""
from __future__ import annotations

import asyncio
import logging
import os
import re
import socket
from collections.abc import Callable
from pathlib import Path

from aiohttp import web

from drem_live.app_code import wake_socket_path

log = logging.getLogger("drem_live")
EVENT_ID = re.compile(rb"[A-Za-z0-9_.-]{1,128}")


class WakeProtocol(asyncio.DatagramProtocol):
    def __init__(self, on_wake: Callable[[str], None]) -> None:
        self._on_wake = on_wake
        self.received = 0

    def datagram_received(self, data: bytes, addr: object) -> None:
        if EVENT_ID.fullmatch(data):
            self.received += 1
            self._on_wake(data.decode())


WAKE: web.AppKey[WakeProtocol] = web.AppKey("wake", WakeProtocol)


def listen_for_wakes(app: web.Application, directory: str, on_wake: Callable[[str], None]) -> None:
    """Bind this process's wake socket while `app` runs (on_startup/on_cleanup); `on_wake(event_id)` per datagram."""
    path = wake_socket_path(directory, os.getpid())
    transport: list[asyncio.DatagramTransport] = []

    async def start(_app: web.Application) -> None:
        try:
            Path(directory).mkdir(mode=0o700, parents=True, exist_ok=True)
            path.unlink(missing_ok=True)
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
            sock.bind(str(path))
            os.chmod(path, 0o600)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            made, protocol = await asyncio.get_running_loop().create_datagram_endpoint(
                lambda: WakeProtocol(on_wake), sock=sock)
        except OSError as exc:  # e.g. a path longer than a socket address: the poll still serves every change
            log.warning("no wake socket at %s (%s): the live server only polls", path, exc)
            return
        transport.append(made)
        app[WAKE] = protocol
        log.info("woken by writes through %s", path)

    async def stop(_app: web.Application) -> None:
        for made in transport:
            made.close()
        path.unlink(missing_ok=True)

    app.on_startup.append(start)
    app.on_cleanup.append(stop)
