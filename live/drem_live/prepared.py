"""A poll's whole HTTP answer (status line, headers, body) built once per view and written in one piece.

Every spectator polling one version gets the same bytes but for the Date line, so the bytes are built when the view
is read and again only when the second on the Date line changes. Profiled under wrk (one live worker, one core),
aiohttp's per-answer work of a `web.Response` (its header multidict, filling in Content-Length, Date and Server,
serialising the headers, joining them to the body) was the largest cost of a poll after the socket write itself.

Only an HTTP/1.1 GET that keeps its connection open takes this path (`takes_prepared`); HEAD, HTTP/1.0 and
`Connection: close` get the same headers through aiohttp's own `web.Response`, which adds what those need. The
answers are identical apart from the Date (tests/unit/test_live_polls_wire.py compares them byte for byte, so
an aiohttp upgrade that changed either is caught).
"""
from __future__ import annotations

from collections.abc import Mapping

from aiohttp import web
from aiohttp.abc import AbstractStreamWriter
from aiohttp.helpers import rfc822_formatted_time
from aiohttp.http import SERVER_SOFTWARE, HttpVersion11

_REASONS = {200: "OK", 304: "Not Modified"}


def takes_prepared(request: web.BaseRequest) -> bool:
    return request.version == HttpVersion11 and request.method == "GET" and request.keep_alive


class WireAnswer:
    """One answer as bytes: `status` with `headers` (in this order), Content-Length when there is a body, then Date
    and Server as aiohttp sends them."""
    __slots__ = ("status", "_head", "_tail", "_date", "_wire")

    def __init__(self, status: int, headers: Mapping[str, str], body: bytes = b"") -> None:
        fields = dict(headers)
        if body:
            fields["Content-Length"] = str(len(body))
        for name, value in fields.items():  # a header that could end the head early would split the answer
            if any(c in name or c in value for c in "\r\n\0") or ":" in name:
                raise ValueError(f"refusing to send the header {name!r}: {value!r}")
        lines = [f"HTTP/1.1 {status} {_REASONS[status]}", *(f"{name}: {value}" for name, value in fields.items())]
        self.status = status
        self._head = ("\r\n".join(lines) + "\r\nDate: ").encode("latin-1")
        self._tail = f"\r\nServer: {SERVER_SOFTWARE}\r\n\r\n".encode("latin-1") + body
        self._date = ""
        self._wire = b""

    def now(self) -> bytes:
        date = rfc822_formatted_time()  # aiohttp's own, formatted once a second
        if date != self._date:
            self._wire = self._head + date.encode("latin-1") + self._tail
            self._date = date
        return self._wire


class PreparedResponse(web.StreamResponse):
    """Writes a `WireAnswer` as it is, in one write: aiohttp's own header building is skipped. Only for a request
    that `takes_prepared`."""

    def __init__(self, answer: WireAnswer) -> None:
        super().__init__(status=answer.status, reason=_REASONS[answer.status])
        self._wire = answer.now()

    async def prepare(self, request: web.BaseRequest) -> AbstractStreamWriter | None:
        if self._eof_sent:
            return None
        if self._payload_writer is None:
            self._req = request
            self._keep_alive = True
            self._payload_writer = request.writer
        return self._payload_writer

    async def write_eof(self, data: bytes = b"") -> None:
        await super().write_eof(self._wire)
