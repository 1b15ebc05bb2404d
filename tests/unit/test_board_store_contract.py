"""The in-memory board store of the fast domain tier (tests/in_memory/boards.py) behaves as DynamoBoardStore does (over
moto) on every point LeaderboardPublisher relies on: each assertion here runs against both."""
from __future__ import annotations

from typing import Any

import pytest

from chalicelib.domain.leaderboards import Materialised, PublicView, StaleBoard
from tests.in_memory.boards import InMemoryBoardStore, page_sort_key

pytestmark = pytest.mark.unit


@pytest.fixture(params=["in_memory", "dynamodb"])
def store(request: pytest.FixtureRequest) -> Any:
    if request.param == "in_memory":
        return InMemoryBoardStore()
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.leaderboards import DynamoBoardStore

    request.getfixturevalue("stack")
    return DynamoBoardStore(clients.dynamodb(), get_settings().table("leaderboards"))


def a_board(version: int, body: str = '{"entries": []}', state: str = '{"rows": []}',
            pages: tuple[str, ...] = ()) -> Materialised:
    return Materialised(version=version, etag=f'"v{version}"', body=body, state=state, pages=pages)


def test_the_adapters_page_key_is_the_one_copied() -> None:
    from chalicelib.storage.leaderboards import page_sort_key as adapters

    assert page_sort_key("BOARD#1", 2) == adapters("BOARD#1", 2)


def test_a_board_reads_back_whole_for_its_writer_and_without_state_for_polls(store: Any) -> None:
    assert store.get("e1", "BOARD#1") is None and store.public("e1", "BOARD#1") is None
    store.put("e1", "BOARD#1", a_board(1), expected_version=None)
    assert store.get("e1", "BOARD#1") == a_board(1)
    assert store.public("e1", "BOARD#1") == PublicView(version=1, etag='"v1"', body='{"entries": []}')
    assert store.public("e1", "BOARD#2") is None and store.public("e2", "BOARD#1") is None


def test_writes_are_conditional_on_the_version_read(store: Any) -> None:
    with pytest.raises(StaleBoard):  # nothing stored yet: only a create may write
        store.put("e1", "BOARD#1", a_board(2), expected_version=1)
    store.put("e1", "BOARD#1", a_board(1, body="first"), expected_version=None)
    with pytest.raises(StaleBoard):  # a second creator
        store.put("e1", "BOARD#1", a_board(1, body="second"), expected_version=None)
    store.put("e1", "BOARD#1", a_board(2, body="two"), expected_version=1)
    with pytest.raises(StaleBoard):  # a writer still on version 1
        store.put("e1", "BOARD#1", a_board(2, body="stale"), expected_version=1)
    assert store.get("e1", "BOARD#1").body == "two"


def test_a_long_boards_pages_are_read_by_page_and_go_when_it_gets_shorter(store: Any) -> None:
    store.put("e1", "BOARD#1", a_board(1, pages=("page two", "page three")), expected_version=None)
    assert [store.public("e1", page_sort_key("BOARD#1", n)).body for n in (2, 3)] == ["page two", "page three"]
    assert store.get("e1", "BOARD#1").pages == ()  # the writer's to put, never read back

    store.put("e1", "BOARD#1", a_board(2, pages=("page two", "new three")), expected_version=1)
    second, third = (store.public("e1", page_sort_key("BOARD#1", n)) for n in (2, 3))
    assert (second.body, second.version) == ("page two", 1)  # unchanged: not written again
    assert (third.body, third.version) == ("new three", 2)
    assert second.etag != third.etag

    store.put("e1", "BOARD#1", a_board(3, pages=("only two",)), expected_version=2)
    assert store.public("e1", page_sort_key("BOARD#1", 2)).body == "only two"
    assert store.public("e1", page_sort_key("BOARD#1", 3)) is None
