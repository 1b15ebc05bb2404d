"""DynamoDB adapter for the scrutineering queue, kept in the `models` table beside the models it concerns.

Items: pk `SCRUTINEER#QUEUE`, sk `JOB#{modelId}` (one job per model, so enqueuing twice is one conditional put that
loses). The items carry no `gsi1pk`, so the operator listing of models never sees them. Every change is conditional:
a lease only lands on the job as it was read (state, lease and attempt count), and a finish or requeue only when the
lease is still the caller's, so a worker whose lease expired cannot remove the job another worker now drives.
The league's re-drives (domain/league_intake.py) are the same kind of queue under pk `LEAGUE#VERIFY` in the
`league` table.
"""
from __future__ import annotations

from typing import Any

from chalicelib.domain.scrutineer_queue import ScrutineerJob
from chalicelib.storage.aws_errors import all_items, call, write_if

_SERVICE = "The scrutineering queue"
_QUEUE_PK = "SCRUTINEER#QUEUE"


LEAGUE_QUEUE_PK = "LEAGUE#VERIFY"


class DynamoJobStore:
    def __init__(self, client: Any, table: str, *, queue_pk: str = _QUEUE_PK) -> None:
        self._client = client
        self._table = table
        self._queue_pk = queue_pk

    def _key(self, model_id: str) -> dict[str, Any]:
        return {"pk": {"S": self._queue_pk}, "sk": {"S": f"JOB#{model_id}"}}

    def add(self, job: ScrutineerJob) -> bool:
        return write_if(self._client, "put_item", _SERVICE, TableName=self._table,
                        Item={**_to_item(job), **self._key(job.model_id)},
                        ConditionExpression="attribute_not_exists(pk)")

    def get(self, model_id: str) -> ScrutineerJob | None:
        reply = call(self._client, "get_item", _SERVICE, TableName=self._table, Key=self._key(model_id),
                     ConsistentRead=True)
        return _from_item(reply["Item"]) if "Item" in reply else None

    def waiting(self, limit: int) -> list[ScrutineerJob]:
        items = all_items(self._client, "query", _SERVICE, TableName=self._table, ConsistentRead=True,
                          KeyConditionExpression="pk = :pk",
                          ExpressionAttributeValues={":pk": {"S": self._queue_pk}})
        jobs = sorted((_from_item(item) for item in items), key=lambda job: (job.enqueued_at_ms, job.model_id))
        return jobs[:limit]

    def lease(self, job: ScrutineerJob, *, token: str, until_ms: int, now_ms: int) -> bool:
        return write_if(
            self._client, "update_item", _SERVICE, TableName=self._table, Key=self._key(job.model_id),
            UpdateExpression="SET #state = :driving, lease_token = :token, lease_until_ms = :until, "
                             "attempts = :next",
            ConditionExpression="attribute_exists(pk) AND attempts = :attempts AND "
                                "(#state = :queued OR lease_until_ms <= :now)",
            ExpressionAttributeNames={"#state": "state"},
            ExpressionAttributeValues={
                ":driving": {"S": "driving"}, ":queued": {"S": "queued"}, ":token": {"S": token},
                ":until": {"N": str(until_ms)}, ":now": {"N": str(now_ms)},
                ":attempts": {"N": str(job.attempts)}, ":next": {"N": str(job.attempts + 1)}})

    def requeue(self, model_id: str, *, token: str) -> bool:
        return write_if(self._client, "update_item", _SERVICE, TableName=self._table, Key=self._key(model_id),
                        UpdateExpression="SET #state = :queued, lease_until_ms = :zero REMOVE lease_token",
                        ConditionExpression="lease_token = :token",
                        ExpressionAttributeNames={"#state": "state"},
                        ExpressionAttributeValues={":queued": {"S": "queued"}, ":zero": {"N": "0"},
                                                   ":token": {"S": token}})

    def remove(self, model_id: str, *, token: str | None) -> bool:
        if token is None:
            return write_if(self._client, "delete_item", _SERVICE, TableName=self._table, Key=self._key(model_id),
                            ConditionExpression="attribute_exists(pk)")
        return write_if(self._client, "delete_item", _SERVICE, TableName=self._table, Key=self._key(model_id),
                        ConditionExpression="lease_token = :token",
                        ExpressionAttributeValues={":token": {"S": token}})


def _to_item(job: ScrutineerJob) -> dict[str, Any]:
    item: dict[str, Any] = {
        "model_id": {"S": job.model_id}, "owner_sub": {"S": job.owner_sub},
        "track_types": {"L": [{"S": track} for track in job.track_types]},
        "enqueued_at_ms": {"N": str(job.enqueued_at_ms)}, "state": {"S": job.state},
        "attempts": {"N": str(job.attempts)}, "lease_until_ms": {"N": str(job.lease_until_ms)},
    }
    if job.lease_token:
        item["lease_token"] = {"S": job.lease_token}
    return item


def _from_item(item: dict[str, Any]) -> ScrutineerJob:
    return ScrutineerJob(
        model_id=item["model_id"]["S"], owner_sub=item["owner_sub"]["S"],
        track_types=[entry["S"] for entry in item["track_types"]["L"]],
        enqueued_at_ms=int(item["enqueued_at_ms"]["N"]), state=item["state"]["S"],
        attempts=int(item["attempts"]["N"]), lease_until_ms=int(item["lease_until_ms"]["N"]),
        lease_token=item["lease_token"]["S"] if "lease_token" in item else None)
