"""DynamoDB adapter for a track's racer queue: one item in the races table, `EVENT#{eventId}` / `QUEUE#{trackId}`,
with the `RacerQueue` as JSON in `doc` and a `version`; every write is conditional on the version read."""
from __future__ import annotations

from typing import Any

from chalicelib.domain.racer_queue import QueueChanged, RacerQueue
from chalicelib.storage.aws_errors import call, write_if

_SERVICE = "The races table"


def queue_key(event_id: str, track_id: str) -> dict[str, Any]:
    return {"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": f"QUEUE#{track_id}"}}


class DynamoQueueStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    def get(self, event_id: str, track_id: str) -> RacerQueue | None:
        reply = call(self._client, "get_item", _SERVICE, TableName=self._table, Key=queue_key(event_id, track_id),
                     ConsistentRead=True)
        return RacerQueue.model_validate_json(reply["Item"]["doc"]["S"]) if "Item" in reply else None

    def put(self, queue: RacerQueue, *, expected_version: int) -> None:
        condition = "attribute_not_exists(pk)" if expected_version == 0 else "version = :expected"
        values = {} if expected_version == 0 else {"ExpressionAttributeValues": {":expected": {
            "N": str(expected_version)}}}
        item = {**queue_key(queue.event_id, queue.track_id), "doc": {"S": queue.model_dump_json()},
                "version": {"N": str(queue.version)}}
        if not write_if(self._client, "put_item", _SERVICE, TableName=self._table, Item=item,
                        ConditionExpression=condition, **values):
            raise QueueChanged(queue.track_id)
