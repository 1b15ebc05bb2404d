"""Write-ahead journal: length-prefixed, checksummed records in one preallocated file.

A record is `<u32 length><u32 crc32>` followed by `length` bytes of pickle; its sequence number is inside.
The file is zero-filled ahead of the write position (like a database WAL segment), because on ext4 an fdatasync
that also has to commit a new file size costs a journal commit (~4 ms on our virtual disk), while one over
already-allocated blocks costs ~0.1 ms. So the journal's end is not the file's end: reading stops at the first
zero, torn, corrupt or out-of-order record. `Journal.open` overwrites a torn tail with zeros, so records appended
after recovery are never hidden behind garbage. Every append writes a zero header right after its record, so what
follows the last record is always a zero header, unless the process died while writing that very record (a torn
tail, at most one record long). Emptying the journal after a snapshot only zeroes its first
header; older records left further on have lower sequence numbers than anything written next, so reading stops
before them (and the snapshot holds them anyway).
"""
from __future__ import annotations

import logging
import os
import pickle
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

log = logging.getLogger("drem.durable")

_HEADER = struct.Struct("<II")
# No single request comes near this; a larger length can only be garbage from a torn write.
_MAX_RECORD_BYTES = 1 << 30
SEGMENT_BYTES = 4 << 20
_END_MARK = b"\0" * _HEADER.size
# Past this the file is cut back to one segment when emptied, so a burst of big uploads does not pin disk space.
_SHRINK_ABOVE_BYTES = 4 * SEGMENT_BYTES


@dataclass(frozen=True)
class JournalRecord:
    seq: int
    service: str
    environ: dict[str, Any]
    body: bytes


@dataclass
class ReadResult:
    records: list[JournalRecord] = field(default_factory=list)
    valid_bytes: int = 0
    torn_bytes: int = 0  # non-zero bytes after the last good record that are not a good record


def encode(record: JournalRecord) -> bytes:
    payload = pickle.dumps((record.seq, record.service, record.environ, record.body), protocol=pickle.HIGHEST_PROTOCOL)
    return _HEADER.pack(len(payload), zlib.crc32(payload)) + payload


def read_all(path: Path) -> ReadResult:
    """Every intact record from the start, up to the first zero, torn, corrupt or out-of-order one."""
    result = ReadResult()
    if not path.exists():
        return result
    data = path.read_bytes()
    offset = 0
    last_seq = 0
    stale_follows = False
    while len(data) - offset >= _HEADER.size:
        length, checksum = _HEADER.unpack_from(data, offset)
        start = offset + _HEADER.size
        if length == 0 or length > _MAX_RECORD_BYTES or start + length > len(data):
            break
        payload = data[start:start + length]
        if zlib.crc32(payload) != checksum:
            break
        try:
            seq, service, environ, body = pickle.loads(payload)
        except Exception:  # a checksum collision on garbage; treat like a torn record
            break
        if seq <= last_seq:
            stale_follows = True  # an older generation, left behind when the journal was emptied
            break
        result.records.append(JournalRecord(seq, service, environ, body))
        last_seq = seq
        offset = start + length
    result.valid_bytes = offset
    result.torn_bytes = 0 if stale_follows else _torn_length(data, offset)
    return result


def _torn_length(data: bytes, offset: int) -> int:
    """Bytes of the record that was being written when the process died (zero if the tail is clean)."""
    if len(data) - offset >= _HEADER.size:
        length, _ = _HEADER.unpack_from(data, offset)
        if length == 0:
            return 0
        return min(len(data) - offset, _HEADER.size + min(length, _MAX_RECORD_BYTES))
    return len(data.rstrip(b"\0")) - offset if len(data.rstrip(b"\0")) > offset else 0


class Journal:
    """The open journal file. Not thread-safe: the server calls it under its `state` lock (durable.lanes)."""

    def __init__(self, path: Path, *, fsync: bool = True) -> None:
        self.path = path
        self.fsync = fsync
        self._fd: int | None = None
        self._capacity = 0
        self.bytes = 0
        self.records = 0

    def open(self) -> ReadResult:
        """Read what is there, zero out a torn tail, and get ready to write after the last good record."""
        existing = read_all(self.path)
        self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)
        self._capacity = os.fstat(self._fd).st_size
        if existing.torn_bytes:
            log.warning("journal %s: the last record (%d bytes) was only partly written when the server stopped, "
                        "so it was never acknowledged; zeroing it after %d intact records",
                        self.path, existing.torn_bytes, len(existing.records))
            os.pwrite(self._fd, b"\0" * existing.torn_bytes, existing.valid_bytes)
            os.fsync(self._fd)
        self.bytes = existing.valid_bytes
        self.records = len(existing.records)
        self._ensure_capacity(self.bytes + _HEADER.size)
        return existing

    def append(self, record: JournalRecord) -> None:
        assert self._fd is not None, "the journal is closed"
        # The record and a zero header after it, in one write: a reader always finds where the journal ends, even
        # when the record ends inside a longer record of an earlier cycle (left behind by `truncate`). Without it,
        # recovery took those leftovers for a torn tail of megabytes.
        data = encode(record)
        self._ensure_capacity(self.bytes + len(data) + _HEADER.size)
        os.pwrite(self._fd, data + _END_MARK, self.bytes)
        if self.fsync:
            os.fdatasync(self._fd)
        self.bytes += len(data)
        self.records += 1

    @property
    def room(self) -> int:
        """Bytes of records that still fit in the space already allocated (no new disk blocks needed)."""
        return max(0, self._capacity - self.bytes - 2 * _HEADER.size)

    def truncate(self) -> None:
        """Empty the journal (its records are now in a snapshot)."""
        assert self._fd is not None, "the journal is closed"
        if self._capacity > _SHRINK_ABOVE_BYTES:
            os.ftruncate(self._fd, 0)
            self._capacity = 0
            self._ensure_capacity(_HEADER.size)
        else:
            os.pwrite(self._fd, b"\0" * _HEADER.size, 0)
            if self.fsync:
                os.fdatasync(self._fd)
        self.bytes = 0
        self.records = 0

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def _ensure_capacity(self, needed: int) -> None:
        assert self._fd is not None, "the journal is closed"
        if needed <= self._capacity:
            return
        new_capacity = -(-needed // SEGMENT_BYTES) * SEGMENT_BYTES
        chunk = b"\0" * (1 << 20)
        position = self._capacity
        while position < new_capacity:
            position += os.pwrite(self._fd, chunk[:new_capacity - position], position)
        # Written zeros (not fallocate's unwritten extents), so later overwrites need no metadata commit.
        os.fsync(self._fd)
        self._capacity = new_capacity
