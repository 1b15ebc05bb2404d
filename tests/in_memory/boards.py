"""Materialised boards, overlays and the big screen's settings in memory: the port LeaderboardPublisher
(BoardRepository) takes.

Copies chalicelib/storage/leaderboards.py (DynamoBoardStore) as the publisher sees it: an item is its version, etag,
public body and (for the head) the state it was ranked from; `put` with `expected_version` None only creates, any
other must match the stored version (a missing item fails too), and a failed condition raises StaleBoard storing
nothing; a long board's further pages are kept under `page_sort_key(sort_key, N)` (N = 2, 3 ...), each replaced only
by a newer version, and the pages past a board that got shorter are deleted; `public` reads any item without its
state; `get` reads a head with its state (pages are the writer's to put, never read back, as in the adapter).
How the adapter splits a big state into parts is its own affair: here the state is kept whole.
"""
from __future__ import annotations

import hashlib

from chalicelib.domain.leaderboards import Materialised, PublicView, StaleBoard


def page_sort_key(sort_key: str, page: int) -> str:
    """The adapter's key of page N of a board (storage/leaderboards.py `page_sort_key`)."""
    return f"{sort_key}~PAGE#{page}"


def _digest(body: str) -> str:
    return hashlib.sha256(body.encode()).hexdigest()[:16]


class InMemoryBoardStore:
    cache_namespace = "in-memory-boards"  # tells the publisher's read cache these items from another store's

    def __init__(self) -> None:
        self._items: dict[tuple[str, str], str] = {}  # (event, sort key) -> Materialised JSON (pages left out)
        self._page_digests: dict[tuple[str, str], list[str]] = {}  # head -> its further pages' digests

    def public(self, event_id: str, sort_key: str) -> PublicView | None:
        found = self._items.get((event_id, sort_key))
        return PublicView.model_validate_json(found) if found else None

    def get(self, event_id: str, sort_key: str) -> Materialised | None:
        found = self._items.get((event_id, sort_key))
        return Materialised.model_validate_json(found) if found else None

    def put(self, event_id: str, sort_key: str, item: Materialised, expected_version: int | None) -> None:
        stored = self.get(event_id, sort_key)
        if (stored is not None) if expected_version is None else (stored is None
                                                                   or stored.version != expected_version):
            raise StaleBoard(sort_key)
        self._items[(event_id, sort_key)] = item.model_copy(update={"pages": ()}).model_dump_json()
        old = self._page_digests.get((event_id, sort_key), [])
        digests = [_digest(body) for body in item.pages]
        for offset, (body, digest) in enumerate(zip(item.pages, digests, strict=True)):
            page_key = (event_id, page_sort_key(sort_key, offset + 2))
            page = self.public(*page_key)
            unchanged = offset < len(old) and old[offset] == digest
            if not unchanged and (page is None or page.version < item.version):
                self._items[page_key] = PublicView(version=item.version, etag=f'"{digest}"',
                                                   body=body).model_dump_json()
        for page_number in range(len(item.pages), len(old)):
            self._items.pop((event_id, page_sort_key(sort_key, page_number + 2)), None)  # the board got shorter
        self._page_digests[(event_id, sort_key)] = digests
