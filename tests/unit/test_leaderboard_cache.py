"""The per-process cache in front of the leaderboard/overlay polls: a poll is served from memory within the 250 ms
freshness window, read again after it, concurrent pollers share one read, and a write through the publisher (or the
race API) is visible to the very next poll in the same process."""
from __future__ import annotations

import json
import threading
from dataclasses import dataclass, field

import pytest

from chalicelib.domain.leaderboards import (
    LeaderboardPublisher,
    Materialised,
    PublicView,
    PublicViewCache,
    StaleBoard,
    board_key,
)
from tests.unit.race_helpers import Desk
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit


@dataclass
class Seconds:
    now: float = 100.0

    def __call__(self) -> float:
        return self.now


@dataclass
class MemoryBoards:
    """An in-memory BoardRepository that counts the poll reads reaching it."""
    items: dict[tuple[str, str], Materialised] = field(default_factory=dict)
    public_reads: int = 0
    cache_namespace: str = "memory"

    def public(self, event_id: str, sort_key: str) -> PublicView | None:
        self.public_reads += 1
        item = self.items.get((event_id, sort_key))
        return PublicView(version=item.version, etag=item.etag, body=item.body) if item else None

    def get(self, event_id: str, sort_key: str) -> Materialised | None:
        return self.items.get((event_id, sort_key))

    def put(self, event_id: str, sort_key: str, item: Materialised, expected_version: int | None) -> None:
        current = self.items.get((event_id, sort_key))
        if (current.version if current else None) != expected_version:
            raise StaleBoard(sort_key)
        self.items[(event_id, sort_key)] = item

    def set_behind_the_publishers_back(self, version: int) -> None:
        self.items[("e1", board_key("1"))] = Materialised(version=version, etag=f'"v{version}"', body=f"body {version}")


def test_a_poll_within_the_window_is_served_from_memory_and_read_again_after_it() -> None:
    boards, seconds = MemoryBoards(), Seconds()
    publisher = LeaderboardPublisher(boards, lambda: 0, cache=PublicViewCache(250, monotonic=seconds))
    boards.set_behind_the_publishers_back(3)
    assert publisher.board("e1", "1").version == 3
    boards.set_behind_the_publishers_back(4)  # another process wrote: this one may lag by at most 250 ms

    seconds.now += 0.149
    assert publisher.board("e1", "1").version == 3
    assert boards.public_reads == 1
    seconds.now += 0.102  # 251 ms after the read started: expired
    assert publisher.board("e1", "1").body == "body 4"
    assert boards.public_reads == 2


def test_an_entry_past_60_percent_of_the_window_is_refreshed_by_one_asker_while_the_others_keep_it() -> None:
    seconds = Seconds()
    cache = PublicViewCache(250, monotonic=seconds)
    cache.get("k", lambda: PublicView(version=1, etag='"v1"', body="one"))
    seconds.now += 0.2
    started, release = threading.Event(), threading.Event()

    def slow_read() -> PublicView:
        started.set()
        release.wait(5)
        return PublicView(version=2, etag='"v2"', body="two")

    refresher_saw: list[PublicView | None] = []
    refresher = threading.Thread(target=lambda: refresher_saw.append(cache.get("k", slow_read)))
    refresher.start()
    started.wait(5)
    # While the refresh is out, other pollers get the (still fresh) entry at once instead of queueing.
    assert cache.get("k", lambda: pytest.fail("a second read while one is in flight")).version == 1
    release.set()
    refresher.join(5)
    assert [v.version for v in refresher_saw if v] == [2]
    assert cache.get("k", lambda: pytest.fail("fresh entry read again")).version == 2


def test_a_missing_board_is_cached_too_and_each_key_and_store_has_its_own_entry() -> None:
    boards, other_table, cache = MemoryBoards(), MemoryBoards(cache_namespace="other"), PublicViewCache(250)
    publisher = LeaderboardPublisher(boards, lambda: 0, cache=cache)
    for _ in range(3):
        assert publisher.board("e1", "1").version == 0
    assert boards.public_reads == 1
    publisher.overlay("e1", "1")
    publisher.board("e1", "2")
    assert boards.public_reads == 3
    other_table.set_behind_the_publishers_back(7)
    assert LeaderboardPublisher(other_table, lambda: 0, cache=cache).board("e1", "1").version == 7


def test_a_write_through_the_publisher_is_visible_to_the_next_poll_of_any_publisher_in_the_process() -> None:
    from drem_leaderboard.models import RankingMethod

    boards, seconds = MemoryBoards(), Seconds()
    cache = PublicViewCache(250, monotonic=seconds)
    poller = LeaderboardPublisher(boards, lambda: 0, cache=cache)
    assert poller.board("e1", "1").version == 0
    writer = LeaderboardPublisher(boards, lambda: 0, cache=cache)  # a different request, same process
    writer.rebuild("e1", {"1": []}, RankingMethod.BEST_LAP_TIME, ["1"])
    assert poller.board("e1", "1").version == 1  # the clock has not moved: only the invalidation explains it
    assert json.loads(poller.board("e1", "combined").body)["track_id"] == "combined"


def test_concurrent_pollers_of_an_expired_key_share_one_read() -> None:
    release = threading.Event()
    reads: list[int] = []

    def slow_read() -> PublicView:
        reads.append(1)
        release.wait(5)
        return PublicView(version=9, etag='"v9"', body="nine")

    cache = PublicViewCache(250)
    answers: list[PublicView | None] = []
    pollers = [threading.Thread(target=lambda: answers.append(cache.get("k", slow_read))) for _ in range(8)]
    for poller in pollers:
        poller.start()
    threading.Event().wait(0.2)  # let every poller reach the cache
    release.set()
    for poller in pollers:
        poller.join(5)
    assert len(reads) == 1
    assert [a.version for a in answers if a] == [9] * 8


def test_a_read_in_flight_when_a_write_lands_is_not_kept() -> None:
    cache = PublicViewCache(250)
    started, release = threading.Event(), threading.Event()

    def read_before_the_write() -> PublicView:
        started.set()
        release.wait(5)
        return PublicView(version=1, etag='"v1"', body="old")

    reader = threading.Thread(target=lambda: cache.get("k", read_before_the_write))
    reader.start()
    started.wait(5)
    cache.invalidate("k")  # the write finished while the read was still out
    # A poll arriving now does not join the stale read: it reads for itself and sees the write.
    assert cache.get("k", lambda: PublicView(version=2, etag='"v2"', body="new")).version == 2
    release.set()
    reader.join(5)
    assert cache.get("k", lambda: PublicView(version=3, etag='"v3"', body="newer")).version == 2


def test_a_failed_early_refresh_still_serves_the_entry_within_the_window_but_not_after_it() -> None:
    seconds = Seconds()
    cache = PublicViewCache(250, monotonic=seconds)
    cache.get("k", lambda: PublicView(version=1, etag='"v1"', body="one"))

    def failing() -> PublicView:
        raise RuntimeError("table unavailable")

    seconds.now += 0.2
    assert cache.get("k", failing).version == 1
    seconds.now += 0.06
    with pytest.raises(RuntimeError):
        cache.get("k", failing)


def test_a_failed_read_is_not_cached_and_the_next_poll_reads_again() -> None:
    cache = PublicViewCache(250)

    def failing() -> PublicView:
        raise RuntimeError("table unavailable")

    with pytest.raises(RuntimeError):
        cache.get("k", failing)
    assert cache.get("k", lambda: PublicView(version=5, etag='"v5"', body="five")).version == 5


def test_a_lap_through_the_race_api_shows_on_the_next_poll(desk: Desk, scenario: Scenario) -> None:
    eid = scenario.add_racers("alice").add_event().event_id
    assert desk.board(eid)["entries"] == []  # cached now (as an empty board)
    scenario.add_race("alice", laps=[11_111])
    assert [e["fastest_lap_ms"] for e in desk.board(eid)["entries"]] == [11_111]
    overlay = desk.ok(desk.anonymous_get(f"/api/overlay/{eid}?track=1"))
    assert overlay["last_lap_ms"] == 11_111


def test_the_writers_wake_up_makes_the_next_read_of_that_event_reach_storage_and_spares_other_events() -> None:
    """The live server's cache: channels woken together share one read; after `invalidate_event` (the writer's
    wake-up) nobody is handed what was read before the write, a read in flight included."""
    boards, seconds = MemoryBoards(), Seconds()
    cache = PublicViewCache(125, monotonic=seconds)
    publisher = LeaderboardPublisher(boards, lambda: 0, cache=cache)
    boards.set_behind_the_publishers_back(3)
    boards.items[("e2", board_key("1"))] = Materialised(version=7, etag='"v7"', body="other event")
    assert publisher.board("e1", "1").version == 3 and publisher.board("e2", "1").version == 7
    assert publisher.board("e1", "1").version == 3 and boards.public_reads == 2  # shared: no third read

    boards.set_behind_the_publishers_back(4)  # the app's writer, then its wake-up
    cache.invalidate_event("e1")
    assert publisher.board("e1", "1").version == 4
    assert publisher.board("e2", "1").version == 7 and boards.public_reads == 3

    started, release = threading.Event(), threading.Event()

    def read_before_the_write() -> PublicView:
        started.set()
        release.wait(5)
        return PublicView(version=4, etag='"v4"', body="body 4")

    cache.invalidate_event("e1")
    reader = threading.Thread(target=lambda: cache.get(("memory", "e1", board_key("1")), read_before_the_write))
    reader.start()
    started.wait(5)
    boards.set_behind_the_publishers_back(5)
    cache.invalidate_event("e1")  # woken while that read was out: it must not be kept
    release.set()
    reader.join(5)
    assert publisher.board("e1", "1").version == 5
