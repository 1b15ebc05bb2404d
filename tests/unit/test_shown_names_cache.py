"""The league board's shown names, kept per process for a few seconds (chalicelib.domain.shown_names_cache)."""
from __future__ import annotations

import pytest

from chalicelib.domain.shown_names_cache import ShownNamesCache

pytestmark = pytest.mark.unit


class _Profiles:
    def __init__(self) -> None:
        self.names = {"alice": "Alice", "bob": "Bob"}
        self.reads = 0

    def shown_names(self, usernames: list[str]) -> dict[str, str]:
        self.reads += 1
        return {name: self.names[name] for name in usernames}


def test_spectators_polling_the_board_read_the_names_once_and_a_rename_shows_after_the_window() -> None:
    now = [100.0]
    cache = ShownNamesCache(5.0, monotonic=lambda: now[0])
    profiles = _Profiles()

    for _ in range(50):
        assert cache.get(["bob", "alice"], profiles.shown_names) == {"alice": "Alice", "bob": "Bob"}
    assert profiles.reads == 1
    profiles.names["alice"] = "Alicia"
    now[0] += 5.1

    assert cache.get(["alice", "bob"], profiles.shown_names)["alice"] == "Alicia"
    assert cache.get(["alice"], profiles.shown_names) == {"alice": "Alicia"}  # another set of racers: read at once
    assert profiles.reads == 3


def test_a_rename_through_this_process_shows_at_once() -> None:
    cache = ShownNamesCache(5.0)
    profiles = _Profiles()
    cache.get(["alice"], profiles.shown_names)
    profiles.names["alice"] = "Alicia"

    cache.clear()

    assert cache.get(["alice"], profiles.shown_names) == {"alice": "Alicia"}
