"""The board/overlay JSON polls (`/live/api/leaderboard|overlay/{event}?track=`) served from memory.

Each (kind, event, track) is read from storage at most once per `fresh_s` (one read in flight at a time), whatever
the poll rate, and again on the first poll after the writer woke the server for its event. The poll that finds the
view past `fresh_s` starts the re-read and waits for it; polls arriving while that read is in flight get the view
they would have got a moment before, at once, instead of each parking a coroutine on the read (under a crowd that
wait was a few per cent of a worker's CPU). After a wake-up every poll waits for the new read: the change is news.
A re-read never replaces a view with an older version (monotonic). The table is bounded (least recently used out
first), so made-up event ids cannot grow it.
"""
from __future__ import annotations

import asyncio
import time
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace

from drem_live.prepared import WireAnswer

# Public data, no credentials: the same headers on every poll answer (server.py has the stream's).
_POLL_HEADERS = {"Access-Control-Allow-Origin": "*", "X-Content-Type-Options": "nosniff", "Cache-Control": "no-cache"}


# A view past its freshness is still shown while its timed re-read is in flight, up to this many `fresh_s` old (a
# storage read that hangs longer makes every poll wait for it again). A wake-up makes a view infinitely old.
MAX_AGE_WHILE_READING = 2.0


@dataclass(frozen=True)
class CachedView:
    """One view as read, with its answers built once for every poll that gets it: the headers (for aiohttp's own
    response) and the whole answer as bytes (drem_live.prepared), so the hot path builds nothing per request."""
    version: int
    etag: str
    body: bytes
    read_at: float
    headers_304: dict[str, str] = field(default_factory=dict)
    headers_200: dict[str, str] = field(default_factory=dict)
    wire_304: WireAnswer = field(default_factory=lambda: WireAnswer(304, {}))
    wire_200: WireAnswer = field(default_factory=lambda: WireAnswer(200, {}))

    @classmethod
    def of(cls, version: int, etag: str, body: bytes, read_at: float) -> CachedView:
        headers_304 = {**_POLL_HEADERS, "ETag": etag}
        headers_200 = {**headers_304, "Content-Type": "application/json"}
        return cls(version, etag, body, read_at, headers_304, headers_200, WireAnswer(304, headers_304),
                   WireAnswer(200, headers_200, body))


class PollViews:
    def __init__(self, read: Callable[[str, str, str], tuple[int, str]], fresh_s: float, executor: Executor,
                 max_entries: int = 1024) -> None:
        self._read = read  # (kind, event, track) -> (version, body)
        self._fresh_s = fresh_s
        self._executor = executor
        self._max_entries = max_entries
        self._views: OrderedDict[tuple[str, str, str], CachedView] = OrderedDict()
        self._reading: dict[tuple[str, str, str], asyncio.Future[CachedView]] = {}

    def fresh(self, kind: str, event_id: str, track: str) -> CachedView | None:
        """The view from memory while it is fresh, else None (then `get`): no coroutine for a poll answered from
        memory."""
        key = (kind, event_id, track)
        cached = self._views.get(key)
        if cached is None:
            return None
        age = time.monotonic() - cached.read_at
        if age < self._fresh_s or (key in self._reading and age < MAX_AGE_WHILE_READING * self._fresh_s):
            return cached
        return None

    async def get(self, kind: str, event_id: str, track: str) -> CachedView:
        key = (kind, event_id, track)
        cached = self._views.get(key)
        if cached is not None and time.monotonic() - cached.read_at < self._fresh_s:
            return cached
        flight = self._reading.get(key)
        if flight is None:
            flight = asyncio.ensure_future(self._refresh(key, cached))
            self._reading[key] = flight
            flight.add_done_callback(lambda _f: self._reading.pop(key, None))
        return await asyncio.shield(flight)

    def expire(self, event_id: str) -> None:
        """The writer changed `event_id` (drem_live.wake): its views are read again on their next poll."""
        for key, view in list(self._views.items()):
            if key[1] == event_id:
                self._views[key] = replace(view, read_at=float("-inf"))

    async def _refresh(self, key: tuple[str, str, str], cached: CachedView | None) -> CachedView:
        read_at = time.monotonic()
        version, body = await asyncio.get_running_loop().run_in_executor(self._executor, self._read, *key)
        if cached is not None and version < cached.version:  # an eventually consistent read lagging behind
            view = replace(cached, read_at=read_at)
        else:
            view = CachedView.of(version, f'"v{version}"', body.encode(), read_at)
        self._views[key] = view
        self._views.move_to_end(key)
        while len(self._views) > self._max_entries:
            self._views.popitem(last=False)
        return view
