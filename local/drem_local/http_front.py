"""The HTTP server in front of drem's local app (and its `/_storage` gateway): waitress, with limits for a venue.

Why waitress (docs/architecture.md, "The local app server"): it is Pylons' maintained production WSGI server, pure
Python (no compiler, no C extension on the organiser's laptop), and built the way a crowd on one WiFi needs: one
asyncore loop reads and writes every connection, so a slow or half-sent request holds a socket, never a worker; the
application runs on a bounded pool of threads only once a request has arrived whole; a body is spooled to a temporary
file past 512 KiB (never grown in memory) and refused with 413 from its Content-Length before it is read, or as soon
as a chunked one passes the limit; idle connections are closed after `channel_timeout`; the client's address is the
peer's (REMOTE_ADDR), or X-Forwarded-For only from a proxy we were told to trust (`trusted_proxy`).

What drem adds on top, in waitress's own extension points (`HTTPChannel.parser_class`, `BaseWSGIServer.maintenance`
and `channel_class`, waitress/channel.py and waitress/server.py):
- a deadline for a request's headers (`HEADER_TIMEOUT_S`): a client that trickles header bytes to keep a connection
  (slowloris) is cut off, although it is never idle long enough for `channel_timeout`;
- a body limit per path: the app's own routes take at most `APP_MAX_BODY_BYTES`, only `/_storage` (model uploads)
  takes up to the storage server's ceiling.
"""
from __future__ import annotations

import copy
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from waitress.channel import HTTPChannel
from waitress.parser import HTTPRequestParser
from waitress.server import TcpWSGIServer, create_server
from waitress.wasyncore import close_all

HEADER_TIMEOUT_S = 15.0
IDLE_TIMEOUT_S = 60
APP_MAX_BODY_BYTES = 20 * 1024 * 1024  # the largest body an app route takes: a booth run's 16 MiB controls file
MAX_HEADER_BYTES = 64 * 1024
# Open connections (phones keep theirs alive): past this the server stops accepting until some close. With poll()
# instead of select() the 1024-descriptor ceiling does not apply.
CONNECTION_LIMIT = 4000
DEFAULT_THREADS = 16

WSGIApp = Callable[[dict[str, Any], Callable[..., Any]], Iterable[bytes]]


@dataclass(frozen=True)
class FrontLimits:
    threads: int = DEFAULT_THREADS
    header_timeout_s: float = HEADER_TIMEOUT_S
    idle_timeout_s: int = IDLE_TIMEOUT_S
    max_header_bytes: int = MAX_HEADER_BYTES
    max_body_bytes: int = APP_MAX_BODY_BYTES
    # Longer-lived allowances by path prefix, e.g. {"/_storage/": 257 MiB}: the first matching prefix wins.
    body_limit_by_prefix: tuple[tuple[str, int], ...] = ()
    connection_limit: int = CONNECTION_LIMIT
    trusted_proxy: str | None = None  # the one address whose X-Forwarded-For names the client

    def body_limit_for(self, path: str) -> int:
        for prefix, limit in self.body_limit_by_prefix:
            if path == prefix.rstrip("/") or path.startswith(prefix):
                return limit
        return self.max_body_bytes

    @property
    def largest_body(self) -> int:
        return max([self.max_body_bytes, *(limit for _prefix, limit in self.body_limit_by_prefix)])


def _parser_class(limits: FrontLimits) -> type[HTTPRequestParser]:
    class Parser(HTTPRequestParser):
        """waitress's parser, with the body limit of the request's path and the time its first byte came."""

        def __init__(self, adj: Any) -> None:
            super().__init__(adj)
            self.started = time.monotonic()

        def parse_header(self, header_plus: bytes) -> None:
            super().parse_header(header_plus)
            # waitress compares Content-Length (and a chunked body as it arrives) against adj.max_request_body_size
            # right after this returns: a copy with this path's limit makes it refuse with 413 before reading.
            limit = limits.body_limit_for(self.path or "")
            adj: Any = getattr(self, "adj")  # noqa: B009 (waitress is untyped: mypy cannot type the attribute)
            if limit + 1 != adj.max_request_body_size:
                adj = copy.copy(adj)
                adj.max_request_body_size = limit + 1  # waitress refuses at >= its limit; `limit` itself is fine
                setattr(self, "adj", adj)  # noqa: B010

    return Parser


def _channel_class(limits: FrontLimits) -> type[HTTPChannel]:
    class Channel(HTTPChannel):
        parser_class = _parser_class(limits)

    return Channel


def _cut_slow_headers(server: TcpWSGIServer, limits: FrontLimits) -> None:
    """Extend the server's periodic sweep (idle connections) with the header deadline."""
    idle_sweep = server.maintenance

    def maintenance(now: float) -> None:
        idle_sweep(now)
        deadline = time.monotonic() - limits.header_timeout_s
        for channel in list(server.active_channels.values()):
            request = channel.request
            if request is not None and not request.headers_finished and request.started < deadline:
                channel.will_close = True

    server.maintenance = maintenance


class FrontServer:
    """A waitress server bound to host:port (port 0: a free one, see `server_address`), stoppable from any thread."""

    def __init__(self, app: WSGIApp, host: str, port: int, limits: FrontLimits | None = None,
                 ident: str = "drem") -> None:
        self.limits = limits or FrontLimits()
        options: dict[str, Any] = {
            "host": host, "port": port, "threads": self.limits.threads, "ident": ident,
            "channel_timeout": self.limits.idle_timeout_s,
            "cleanup_interval": max(1, int(self.limits.header_timeout_s // 3)),
            "max_request_header_size": self.limits.max_header_bytes,
            "max_request_body_size": self.limits.largest_body + 1,
            "connection_limit": self.limits.connection_limit,
            "asyncore_use_poll": True,
            "expose_tracebacks": False,
            # A phone that closes a tab mid-answer is normal on event day, not an error with a traceback.
            "log_socket_errors": False,
        }
        if self.limits.trusted_proxy:
            options.update(trusted_proxy=self.limits.trusted_proxy, trusted_proxy_count=1,
                           trusted_proxy_headers={"x-forwarded-for"}, clear_untrusted_proxy_headers=True)
        server = create_server(app, **options)
        assert isinstance(server, TcpWSGIServer), "one listening address"
        server.channel_class = _channel_class(self.limits)
        _cut_slow_headers(server, self.limits)
        self._server = server
        self._stopping = threading.Event()
        self._stopped = threading.Event()

    @property
    def server_address(self) -> tuple[str, int]:
        return str(self._server.effective_host), int(self._server.effective_port)

    def serve_forever(self, poll_interval: float = 0.5) -> None:
        server = self._server
        try:
            while not self._stopping.is_set():
                server.asyncore.loop(timeout=poll_interval, map=server._map, use_poll=True, count=1)
        finally:
            server.task_dispatcher.shutdown(timeout=5)
            close_all(server._map)
            self._stopped.set()

    def shutdown(self) -> None:
        """Stop serving (from another thread): the loop ends within `poll_interval`, connections are closed."""
        self._stopping.set()
        self._stopped.wait(10)

    def server_close(self) -> None:
        self._stopping.set()
