"""DynamoDB adapter for the `leaderboards` table: materialised boards and overlays, each read with one GetItem.

| item | pk | sk |
|---|---|---|
| board of a track, or of all tracks (`BOARD#combined`) | `EVENT#{eventId}` | `BOARD#{trackId}` |
| overlay (live race state) of a track | `EVENT#{eventId}` | `OVERLAY#{trackId}` |

Each item holds `version` (bumped on every visible change), `etag`, `body` (the public JSON, already serialised, so a
poll is GetItem + return) and, for boards, `state` (the racer summaries the board was ranked from, so one racer's
change re-ranks without reading every race). Writes are conditional on the version read (`StaleBoard` on a clash).
"""
from __future__ import annotations

from typing import Any

from chalicelib.domain.leaderboards import Materialised, PublicView, StaleBoard
from chalicelib.storage.aws_errors import call, write_if

_SERVICE = "The leaderboards table"


def item_key(event_id: str, sort_key: str) -> dict[str, Any]:
    return {"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": sort_key}}


class DynamoBoardStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

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
        item = self._call("get_item", TableName=self._table, Key=item_key(event_id, sort_key),
                          ConsistentRead=True).get("Item")
        if not item:
            return None
        return Materialised(version=int(item["version"]["N"]), etag=item["etag"]["S"], body=item["body"]["S"],
                            state=item.get("state", {}).get("S", ""))

    def put(self, event_id: str, sort_key: str, item: Materialised, expected_version: int | None) -> None:
        """Write version `item.version`; `expected_version` None means "must not exist yet"."""
        stored = {**item_key(event_id, sort_key), "version": {"N": str(item.version)}, "etag": {"S": item.etag},
                  "body": {"S": item.body}, "state": {"S": item.state}}
        kwargs: dict[str, Any] = {"TableName": self._table, "Item": stored}
        if expected_version is None:
            kwargs["ConditionExpression"] = "attribute_not_exists(pk)"
        else:
            kwargs["ConditionExpression"] = "version = :expected"
            kwargs["ExpressionAttributeValues"] = {":expected": {"N": str(expected_version)}}
        if not write_if(self._client, "put_item", _SERVICE, **kwargs):
            raise StaleBoard(sort_key)

    def _call(self, operation: str, **kwargs: Any) -> dict[str, Any]:
        return call(self._client, operation, _SERVICE, **kwargs)
