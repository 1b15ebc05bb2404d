"""Byte-stream wrappers for reading an archive once, counting every byte on both sides of the decompressor."""
from __future__ import annotations

import io
from collections import deque
from collections.abc import Callable
from typing import IO


class CountingReader(io.RawIOBase):
    """Passes reads through and raises `problem()` once more than `limit` bytes went by."""

    def __init__(self, inner: IO[bytes], limit: int, problem: Callable[[], Exception]) -> None:
        self._inner = inner
        self._limit = limit
        self._problem = problem
        self.count = 0

    def readable(self) -> bool:
        return True

    def read(self, size: int = -1) -> bytes:
        # Never let an unbounded read through: it is what a bomb relies on.
        wanted = self._limit + 1 - self.count if size is None or size < 0 else size
        data = self._inner.read(max(0, min(wanted, self._limit + 1 - self.count)))
        self.count += len(data)
        if self.count > self._limit:
            raise self._problem()
        return data

    def readinto(self, buffer) -> int:  # type: ignore[override]
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)


class TailWindow(io.RawIOBase):
    """Passes reads through, counting the position and keeping the last `window` bytes read, so the bytes tarfile
    read ahead past its end marker can be checked too."""

    def __init__(self, inner: IO[bytes], window: int) -> None:
        self._inner = inner
        self._window = window
        self._kept: deque[bytes] = deque()
        self._kept_bytes = 0
        self.position = 0

    def readable(self) -> bool:
        return True

    def read(self, size: int = -1) -> bytes:
        data = self._inner.read(size)
        self.position += len(data)
        self._kept.append(data)
        self._kept_bytes += len(data)
        while self._kept and self._kept_bytes - len(self._kept[0]) >= self._window:
            self._kept_bytes -= len(self._kept.popleft())
        return data

    def readinto(self, buffer) -> int:  # type: ignore[override]
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)

    def since(self, offset: int) -> bytes | None:
        """The bytes read from `offset` up to the current position, or None if they are no longer kept."""
        start = self.position - self._kept_bytes
        if offset < start or offset > self.position:
            return None
        return b"".join(self._kept)[offset - start:]


class Prefixed(io.RawIOBase):
    """Puts back the magic bytes we peeked at, for sources that cannot seek."""

    def __init__(self, prefix: bytes, rest: IO[bytes]) -> None:
        self._prefix = prefix
        self._rest = rest

    def readable(self) -> bool:
        return True

    def read(self, size: int = -1) -> bytes:
        if self._prefix:
            taken = self._prefix if size is None or size < 0 else self._prefix[:size]
            self._prefix = self._prefix[len(taken):]
            return taken
        return self._rest.read(size)

    def readinto(self, buffer) -> int:  # type: ignore[override]
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)
