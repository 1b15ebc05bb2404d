"""DynamoDB adapter for the statistics digests (`domain/stats.py`): one item per event in the `races` table.

  statistics digest   EVENT#{eventId} / STATS   `EventDigest` as JSON in `doc`; `listedAtMs`: when the race listing
                                                it was built from began

It sits in the event's partition, beside its races, but is not a race: listings read `RACE#` items only, and an
event export carries races and audit entries only (the target builds its own digest on first read). A put replaces
the stored digest only if it was built from a later listing, so a slower, older rebuild never overwrites a newer one.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from chalicelib.domain.stats import EventDigest
from chalicelib.storage.aws_errors import batch_items, write_if

_SERVICE = "The races table"
_SK = "STATS"


def _key(event_id: str) -> dict[str, Any]:
    return {"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": _SK}}


class DynamoStatsDigestStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    def digests(self, event_ids: Sequence[str]) -> dict[str, EventDigest]:
        found: dict[str, EventDigest] = {}
        keys = [_key(event_id) for event_id in dict.fromkeys(event_ids)]
        for item in batch_items(self._client, self._table, keys, _SERVICE, ConsistentRead=True,
                                ProjectionExpression="doc"):
            digest = EventDigest.model_validate_json(item["doc"]["S"])
            found[digest.event_id] = digest
        return found

    def put(self, digest: EventDigest, listed_at_ms: int) -> None:
        # Not written when a digest built from a later listing is already stored: that one wins.
        write_if(self._client, "put_item", _SERVICE, TableName=self._table,
                 Item={**_key(digest.event_id), "doc": {"S": digest.model_dump_json()},
                       "listedAtMs": {"N": str(listed_at_ms)}},
                 ConditionExpression="attribute_not_exists(pk) OR listedAtMs <= :listed",
                 ExpressionAttributeValues={":listed": {"N": str(listed_at_ms)}})
