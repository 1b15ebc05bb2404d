"""Server-sent events framing, and gzip that is compressed once per message for every subscriber.

A gzip stream is a 10-byte header followed by a raw deflate stream (RFC 1952). Each message is deflated on its own
(a fresh compressor) and ended with a full flush (Z_FULL_FLUSH: byte-aligned, no reference to anything before), so
its compressed bytes are a valid continuation of any deflate stream that ends at a flush boundary. One compression per
broadcast then serves every subscriber: each stream is `GZIP_HEADER` + the chunks of the messages it was sent. The
stream never ends with a trailer (it ends when the connection does); browsers decode it as it arrives.
"""
from __future__ import annotations

import re
import zlib
from dataclasses import dataclass

GZIP_HEADER = b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x00\xff"  # deflate, no name, no mtime, unknown OS
COMPRESSION_LEVEL = 6
_LINE_BREAK = re.compile(r"\r\n|\r|\n")


def deflate_chunk(data: bytes) -> bytes:
    """`data` as independent raw-deflate bytes (ends on a full flush, so chunks can follow each other in any order)."""
    compressor = zlib.compressobj(COMPRESSION_LEVEL, zlib.DEFLATED, -zlib.MAX_WBITS)
    return compressor.compress(data) + compressor.flush(zlib.Z_FULL_FLUSH)


def event_bytes(event: str, data: str, event_id: str | None = None, retry_ms: int | None = None) -> bytes:
    """One SSE message; every line of `data` becomes a `data:` line (the browser joins them with newlines)."""
    head = f"id: {event_id}\n" if event_id is not None else ""
    if retry_ms is not None:
        head += f"retry: {retry_ms}\n"
    lines = "".join(f"data: {line}\n" for line in _LINE_BREAK.split(data))
    return f"{head}event: {event}\n{lines}\n".encode()


@dataclass(frozen=True)
class Message:
    """One SSE message in both encodings, built once and written to every subscriber."""
    token: str
    plain: bytes
    gzip: bytes

    @classmethod
    def of(cls, raw: bytes, token: str = "") -> Message:
        return cls(token, raw, deflate_chunk(raw))

    @classmethod
    def fragment(cls, token: str, html: str) -> Message:
        return cls.of(event_bytes("fragment", html, event_id=token), token)

    def bytes_for(self, gzip: bool) -> bytes:
        return self.gzip if gzip else self.plain


HEARTBEAT = Message.of(b": heartbeat\n\n")


def clock_message(now_ms: int, retry_ms: int) -> Message:
    """Sent to one subscriber before its first fragment, which may have been built a while ago: live.js advances the
    fragment's running clocks by (this time - the time they were read)."""
    return Message.of(event_bytes("clock", str(now_ms), retry_ms=retry_ms))


def accepts_gzip(accept_encoding: str) -> bool:
    for part in accept_encoding.split(","):
        name, _, params = part.strip().partition(";")
        if name.strip().lower() in ("gzip", "*"):
            q = params.strip().lower()
            try:
                return not (q.startswith("q=") and float(q[2:] or 0) == 0)
            except ValueError:
                return False
    return False
