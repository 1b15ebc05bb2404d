"""DynamoDB adapter for the `leaderboards` table: materialised boards and overlays, each poll read with one GetItem.

| item | pk | sk |
|---|---|---|
| board of a track, or of all tracks (`BOARD#combined`): its first page | `EVENT#{eventId}` | `BOARD#{trackId}` |
| page N (2, 3, ...) of a board longer than one page | `EVENT#{eventId}` | `BOARD#{trackId}~PAGE#{N}` |
| part I of a big board's ranking state, written by write REF | `EVENT#{eventId}` | `BOARD#{trackId}~STATE#{REF}#{I}` |
| overlay (live race state) of a track | `EVENT#{eventId}` | `OVERLAY#{trackId}` |
| the big screen's settings around the board (name, sponsor, logo, footers) | `EVENT#{eventId}` | `SCREEN` |

The head item holds `version` (bumped on every visible change), `etag`, `body` (the public JSON of the first page,
already serialised, so a poll is GetItem + return) and, for track boards, the racer summaries the board was ranked
from (so one racer's change re-ranks without reading every race): inline as `state` while that is small, otherwise
zlib-compressed in parts of at most PART_BYTES, named by `state_ref` and `state_parts`. No item nears DynamoDB's
400 KB limit at 5,000 racers per track: a page holds BOARD_PAGE_ENTRIES entries (~65 KB) and a part PART_BYTES.

Writes are conditional on the head's version (`StaleBoard` on a clash). A big state's parts are written first under a
fresh `state_ref` the head then names, so a writer that loses the race never touches the winner's parts (it deletes
its own), and a crash between the two leaves only unnamed parts. Further pages are written after the head, each only
when it changed (the head keeps a digest per page) and never over a newer version, so a page is at most one write
behind its head.
"""
from __future__ import annotations

import hashlib
import uuid
import zlib
from typing import Any

from chalicelib.domain.leaderboards import Materialised, PublicView, StaleBoard
from chalicelib.storage.aws_errors import batch_items, call, write_if

_SERVICE = "The leaderboards table"
INLINE_STATE_BYTES = 200_000  # the state stays plain in the head up to this (small boards: as they always were)
PART_BYTES = 300_000  # compressed state per part item
ITEM_LIMIT_BYTES = 390_000  # refuse clearly before DynamoDB's 400 KB limit does obscurely
_GET_ATTEMPTS = 4


def item_key(event_id: str, sort_key: str) -> dict[str, Any]:
    return {"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": sort_key}}


def page_sort_key(sort_key: str, page: int) -> str:
    return f"{sort_key}~PAGE#{page}"


def part_sort_key(sort_key: str, ref: str, index: int) -> str:
    return f"{sort_key}~STATE#{ref}#{index}"


def _digest(body: str) -> str:
    return hashlib.sha256(body.encode()).hexdigest()[:16]


class DynamoBoardStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table
        # What `get` last saw a head name (parts, page digests), by key: `put` replaces them without reading again.
        self._layouts: dict[tuple[str, str], tuple[int, dict[str, Any]]] = {}

    @property
    def cache_namespace(self) -> str:
        """Tells the publisher's per-process read cache this store's items from another table's."""
        return self._table

    def public(self, event_id: str, sort_key: str) -> PublicView | None:
        """The hot read: one GetItem, without the ranking state."""
        item = self._call("get_item", TableName=self._table, Key=item_key(event_id, sort_key),
                          ProjectionExpression="version, etag, body").get("Item")
        if not item:
            return None
        return PublicView(version=int(item["version"]["N"]), etag=item["etag"]["S"], body=item["body"]["S"])

    def get(self, event_id: str, sort_key: str) -> Materialised | None:
        for _ in range(_GET_ATTEMPTS):
            item = self._call("get_item", TableName=self._table, Key=item_key(event_id, sort_key),
                              ConsistentRead=True).get("Item")
            if not item:
                return None
            state = self._state(event_id, sort_key, item)
            if state is not None:
                self._layouts[(event_id, sort_key)] = (int(item["version"]["N"]), {
                    name: item[name] for name in ("state_ref", "state_parts", "page_digests") if name in item})
                return Materialised(version=int(item["version"]["N"]), etag=item["etag"]["S"],
                                    body=item["body"]["S"], state=state)
            # The parts it names were just replaced by a newer write (and deleted): read the newer head.
        raise StaleBoard(sort_key)

    def put(self, event_id: str, sort_key: str, item: Materialised, expected_version: int | None) -> None:
        """Write version `item.version`; `expected_version` None means "must not exist yet"."""
        previous = self._previous_layout(event_id, sort_key, expected_version)
        stored = {**item_key(event_id, sort_key), "version": {"N": str(item.version)}, "etag": {"S": item.etag},
                  "body": {"S": item.body}}
        new_parts: list[str] = []
        if len(item.state.encode()) <= INLINE_STATE_BYTES:
            stored["state"] = {"S": item.state}
        else:
            ref = uuid.uuid4().hex[:12]
            new_parts = self._write_parts(event_id, sort_key, ref, zlib.compress(item.state.encode(), 6))
            stored |= {"state_ref": {"S": ref}, "state_parts": {"N": str(len(new_parts))}}
        digests = [_digest(body) for body in item.pages]
        if digests:
            stored["page_digests"] = {"L": [{"S": d} for d in digests]}
        self._check_size(stored, sort_key)
        kwargs: dict[str, Any] = {"TableName": self._table, "Item": stored}
        if expected_version is None:
            kwargs["ConditionExpression"] = "attribute_not_exists(pk)"
        else:
            kwargs["ConditionExpression"] = "version = :expected"
            kwargs["ExpressionAttributeValues"] = {":expected": {"N": str(expected_version)}}
        if not write_if(self._client, "put_item", _SERVICE, **kwargs):
            self._delete(event_id, new_parts)
            raise StaleBoard(sort_key)
        self._write_pages(event_id, sort_key, item, digests, previous)
        self._delete(event_id, self._old_parts(sort_key, previous))

    # --- the layout behind the head ------------------------------------------------------------------------------

    def _state(self, event_id: str, sort_key: str, item: dict[str, Any]) -> str | None:
        if "state_ref" not in item:
            return str(item.get("state", {}).get("S", ""))
        keys = [part_sort_key(sort_key, item["state_ref"]["S"], i) for i in range(int(item["state_parts"]["N"]))]
        found = {part["sk"]["S"]: part["data"]["B"] for part in batch_items(
            self._client, self._table, [item_key(event_id, key) for key in keys], _SERVICE, ConsistentRead=True)}
        if len(found) != len(keys):
            return None
        return zlib.decompress(b"".join(found[key] for key in keys)).decode()

    def _previous_layout(self, event_id: str, sort_key: str, expected_version: int | None) -> dict[str, Any]:
        """What the head being replaced names besides its body: its state parts and its pages' digests."""
        if expected_version is None:
            return {}
        seen = self._layouts.pop((event_id, sort_key), None)
        if seen is not None and seen[0] == expected_version:
            return seen[1]
        return self._call("get_item", TableName=self._table, Key=item_key(event_id, sort_key), ConsistentRead=True,
                          ProjectionExpression="state_ref, state_parts, page_digests").get("Item") or {}

    def _write_parts(self, event_id: str, sort_key: str, ref: str, data: bytes) -> list[str]:
        keys = []
        for index, start in enumerate(range(0, len(data), PART_BYTES)):
            key = part_sort_key(sort_key, ref, index)
            self._call("put_item", TableName=self._table,
                       Item={**item_key(event_id, key), "data": {"B": data[start:start + PART_BYTES]}})
            keys.append(key)
        return keys

    def _write_pages(self, event_id: str, sort_key: str, item: Materialised, digests: list[str],
                     previous: dict[str, Any]) -> None:
        old = [d["S"] for d in previous.get("page_digests", {}).get("L", [])]
        for offset, (body, digest) in enumerate(zip(item.pages, digests, strict=True)):
            if offset < len(old) and old[offset] == digest:
                continue  # unchanged: a racer far down the board rewrites only the pages around them
            stored = {**item_key(event_id, page_sort_key(sort_key, offset + 2)), "version": {"N": str(item.version)},
                      "etag": {"S": f'"{digest}"'}, "body": {"S": body}}
            self._check_size(stored, sort_key)
            write_if(self._client, "put_item", _SERVICE, TableName=self._table, Item=stored,
                     ConditionExpression="attribute_not_exists(pk) OR version < :version",
                     ExpressionAttributeValues={":version": {"N": str(item.version)}})
        gone = [page_sort_key(sort_key, page + 2) for page in range(len(item.pages), len(old))]
        self._delete(event_id, gone)  # the board got shorter

    @staticmethod
    def _old_parts(sort_key: str, previous: dict[str, Any]) -> list[str]:
        if "state_ref" not in previous:
            return []
        return [part_sort_key(sort_key, previous["state_ref"]["S"], i)
                for i in range(int(previous["state_parts"]["N"]))]

    def _delete(self, event_id: str, sort_keys: list[str]) -> None:
        for key in sort_keys:
            self._call("delete_item", TableName=self._table, Key=item_key(event_id, key))

    @staticmethod
    def _check_size(stored: dict[str, Any], sort_key: str) -> None:
        size = sum(len(name) + len(str(value)) for name, value in stored.items())
        if size > ITEM_LIMIT_BYTES:
            raise ValueError(f"board item {sort_key} would be {size} bytes, past DynamoDB's 400 KB item limit")

    def _call(self, operation: str, **kwargs: Any) -> dict[str, Any]:
        return call(self._client, operation, _SERVICE, **kwargs)
