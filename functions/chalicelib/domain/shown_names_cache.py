"""The names the public league board shows, kept per process for a few seconds.

Each board read otherwise made two batch reads (sign-in names to subs, then profiles) on top of the board itself, so a
board with entries cost storage twice the round trips of an empty one, and spectators polling it asked for the same
names again and again (bench/league.py, issue 32). Display names change rarely: a change made through this process
clears the cache (ProfileService), one made through another process shows within `fresh_s`; a different set of
racers on the board is its own key, read at once.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable

SHOWN_NAMES_FRESH_S = 5.0


class ShownNamesCache:
    def __init__(self, fresh_s: float = SHOWN_NAMES_FRESH_S, *, monotonic: Callable[[], float] = time.monotonic,
                 max_entries: int = 1024) -> None:
        self.fresh_s = fresh_s
        self._monotonic = monotonic
        self._max_entries = max_entries
        self._lock = threading.Lock()
        self._entries: dict[tuple[str, ...], tuple[float, dict[str, str]]] = {}

    def get(self, usernames: list[str], load: Callable[[list[str]], dict[str, str]]) -> dict[str, str]:
        """{sign-in name: shown name} of `usernames`, read by `load` at most `fresh_s` ago."""
        key = tuple(sorted(set(usernames)))
        with self._lock:
            held = self._entries.get(key)
        if held is not None and self._monotonic() - held[0] <= self.fresh_s:
            return dict(held[1])
        started = self._monotonic()
        names = load(list(key))
        with self._lock:
            if len(self._entries) >= self._max_entries:
                self._entries.clear()
            self._entries[key] = (started, dict(names))
        return names

    def clear(self) -> None:
        """A profile changed through this process: read every name again."""
        with self._lock:
            self._entries.clear()


PROCESS_SHOWN_NAMES = ShownNamesCache()
