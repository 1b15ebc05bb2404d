"""The ranked league boards, kept per process for a second.

Spectators poll a track's board; each view otherwise read the policy and the board from storage and ranked it again,
and while drem verifies entries those reads queue behind the storage server's model uploads and the worker's writes
(bench/league.py, issue 32). A board is the same for every spectator for a while, so each process keeps the ranked
board of each (track, query) for `fresh_s`:
- one request thread recomputes a board at a time (single flight); the others wait for it, or take the board it
  replaces while that is still fresh;
- a board read is refreshed ahead, once it is `refresh_ahead` of its freshness old, so a steady stream of readers
  rarely waits on storage at all;
- every write through this process's LeagueService drops every board at once (the racer sees their push on the next
  read); a write made by another process (the scrutineering worker storing a re-drive, another app process) shows
  within `fresh_s`, since a board is never served older than that, counted from when its read began.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Generic, TypeVar

LEAGUE_BOARD_FRESH_S = 1.0
REFRESH_AHEAD = 0.6
# A public query names any dates and filters: past this many boards the cache starts over rather than grow.
MAX_BOARDS = 256

Value = TypeVar("Value")


@dataclass(frozen=True)
class _Held(Generic[Value]):
    read_at: float  # when the read that produced it began: its age counts from there
    generation: int
    value: Value


class LeagueBoardCache(Generic[Value]):
    def __init__(self, fresh_s: float = LEAGUE_BOARD_FRESH_S, *, refresh_ahead: float = REFRESH_AHEAD,
                 monotonic: Callable[[], float] = time.monotonic, max_entries: int = MAX_BOARDS) -> None:
        self.fresh_s = fresh_s
        self._ahead_s = fresh_s * refresh_ahead
        self._monotonic = monotonic
        self._max_entries = max_entries
        self._changed = threading.Condition()
        self._held: dict[Hashable, _Held[Value]] = {}
        self._loading: set[tuple[Hashable, int]] = set()
        # Bumped by every write: a read begun before a write is never kept after it.
        self._generation = 0

    def get(self, key: Hashable, load: Callable[[], Value]) -> Value:
        """The value of `key`, read by `load` at most `fresh_s` ago (and after this process's last write)."""
        waited = False
        with self._changed:
            while True:
                generation = self._generation
                held = self._held.get(key)
                loading = (key, generation) in self._loading
                if held is not None and held.generation == generation:
                    age = self._monotonic() - held.read_at
                    # Still fresh: given as it is unless it is due for a refresh ahead that no thread has begun (a
                    # value this thread waited for is taken as it is: the read that made it may have been slow).
                    if age <= self.fresh_s and (age < self._ahead_s or loading or waited):
                        return held.value
                if not loading:
                    break  # this thread reads it: a refresh ahead, or there is no fresh value to give
                self._changed.wait(timeout=self.fresh_s)  # another thread reads it: its value is fresher
                waited = True
            self._loading.add((key, generation))
        try:
            read_at = self._monotonic()
            value = load()
        except BaseException:
            with self._changed:
                self._loading.discard((key, generation))
                self._changed.notify_all()  # a waiter reads it instead
            raise
        with self._changed:
            self._loading.discard((key, generation))
            if self._generation == generation:
                if key not in self._held and len(self._held) >= self._max_entries:
                    self._held.clear()
                self._held[key] = _Held(read_at, generation, value)
            self._changed.notify_all()
        return value

    def clear(self) -> None:
        """Something was written through this process: every board is read again, reads in flight are not kept."""
        with self._changed:
            self._generation += 1
            self._held.clear()
            self._changed.notify_all()


if TYPE_CHECKING:
    from chalicelib.domain.league import Board

PROCESS_LEAGUE_BOARDS: LeagueBoardCache[Board] = LeagueBoardCache()
