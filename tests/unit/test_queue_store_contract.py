"""The in-memory racer queue store of the fast domain tier (tests/in_memory/racer_queue.py) behaves as
DynamoQueueStore does (over moto) on every point RacerQueueService relies on: each assertion here runs against both."""
from __future__ import annotations

from typing import Any

import pytest

from chalicelib.domain.racer_queue import QueueChanged, QueueEntry, RacerQueue
from tests.in_memory.racer_queue import InMemoryQueueStore

pytestmark = pytest.mark.unit


@pytest.fixture(params=["in_memory", "dynamodb"])
def store(request: pytest.FixtureRequest) -> Any:
    if request.param == "in_memory":
        return InMemoryQueueStore()
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.racer_queue import DynamoQueueStore

    request.getfixturevalue("stack")
    return DynamoQueueStore(clients.dynamodb(), get_settings().table("races"))


def a_queue(version: int, *racers: str, track_id: str = "1") -> RacerQueue:
    entries = [QueueEntry(entry_id=f"{racer}-entry", racer_username=racer, racer_sub=f"{racer}-sub", model_id="m",
                          model_name="m", added_by="op", added_at_ms=1) for racer in racers]
    return RacerQueue(event_id="e1", track_id=track_id, entries=entries, version=version)


def test_a_queue_reads_back_as_written_and_a_missing_one_is_none(store: Any) -> None:
    assert store.get("e1", "1") is None
    store.put(a_queue(1, "alice"), expected_version=0)
    assert store.get("e1", "1") == a_queue(1, "alice")
    assert store.get("e1", "2") is None


def test_creating_a_queue_that_exists_is_a_change_and_keeps_the_first(store: Any) -> None:
    store.put(a_queue(1, "alice"), expected_version=0)
    with pytest.raises(QueueChanged):
        store.put(a_queue(1, "bob"), expected_version=0)
    assert store.get("e1", "1") == a_queue(1, "alice")


def test_a_write_on_a_stale_or_missing_version_is_a_change_and_writes_nothing(store: Any) -> None:
    store.put(a_queue(1, "alice"), expected_version=0)
    store.put(a_queue(2, "alice", "bob"), expected_version=1)
    with pytest.raises(QueueChanged):
        store.put(a_queue(2, "carol"), expected_version=1)
    assert store.get("e1", "1") == a_queue(2, "alice", "bob")
    with pytest.raises(QueueChanged):
        store.put(a_queue(4, "dave", track_id="2"), expected_version=3)
    assert store.get("e1", "2") is None
