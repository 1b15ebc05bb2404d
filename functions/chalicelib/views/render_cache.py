"""Per-process caches of things built from versioned inputs, shared by every poller of a live page.

After a lap, every spectator's next poll asks for the same new fragment: same event, same options, same version token
(the token names every board/overlay item version, and the overlay phase, the fragment was built from). Building it
once and handing the same HTML to all of them turns N renders (and N race reads) into one.

- **Exact-key validity**: a key carries the versions its value was built from, so an entry is never stale; it is only
  ever evicted (least recently used first, `max_entries` bound). Anything in a value that depends on wall time must be
  anchored in the value itself and advanced by the client (the live fragments carry `data-clock-at`; see live.js).
- **Single flight**: while one thread builds a key, the others asking for it wait for that build instead of building
  too. A failed build is not cached (the waiters then build for themselves).
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from drem_leaderboard.models import Race

Value = TypeVar("Value")

FRAGMENT_ENTRIES = 256
RACE_ENTRIES = 128


@dataclass
class _Flight(Generic[Value]):
    done: threading.Event = field(default_factory=threading.Event)
    value: Value | None = None
    ok: bool = False


class VersionedCache(Generic[Value]):
    """Bounded (LRU), single-flight map from a versioned key to what was built for it."""

    def __init__(self, max_entries: int, *, wait_s: float = 5.0) -> None:
        if max_entries < 1:
            raise ValueError("max_entries must be at least 1")
        self._max_entries = max_entries
        self._wait_s = wait_s
        self._lock = threading.Lock()
        self._entries: OrderedDict[Hashable, Value] = OrderedDict()
        self._flights: dict[Hashable, _Flight[Value]] = {}

    def get(self, key: Hashable, build: Callable[[], Value]) -> Value:
        with self._lock:
            if key in self._entries:
                self._entries.move_to_end(key)
                return self._entries[key]
            flight = self._flights.get(key)
            leader = flight is None
            if flight is None:
                flight = self._flights[key] = _Flight()
        if not leader:
            if flight.done.wait(self._wait_s) and flight.ok:
                return flight.value  # type: ignore[return-value]
            return build()  # the leader failed or hung: build (and fail) on our own
        try:
            value = build()
        except BaseException:
            with self._lock:
                self._flights.pop(key, None)
            flight.done.set()
            raise
        with self._lock:
            self._flights.pop(key, None)
            self._entries[key] = value
            self._entries.move_to_end(key)
            while len(self._entries) > self._max_entries:
                self._entries.popitem(last=False)
            flight.value, flight.ok = value, True
        flight.done.set()
        return value

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)

    def __contains__(self, key: Hashable) -> bool:
        with self._lock:
            return key in self._entries

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()


# The live pages' fragment HTML, keyed by (fragment, base path, event, options, version token).
LIVE_FRAGMENTS: VersionedCache[str] = VersionedCache(FRAGMENT_ENTRIES)
# The race behind an overlay, keyed by (event, track, race id, overlay version): every race change republishes the
# overlay with a new version after storing the race, so a (consistent) read made after seeing version v is at least
# as new as v.
LIVE_RACES: VersionedCache[Race | None] = VersionedCache(RACE_ENTRIES)
