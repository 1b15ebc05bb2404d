"""DynamoDB adapter for the results audit trail: items in the `races` table, next to the event's races.

| item | pk | sk |
|---|---|---|
| audit entry (`AuditEntry` as JSON in `doc`, plus `action`) | `EVENT#{eventId}` | `AUDIT#{atMs:013d}#{entryId}` |

The sort key orders entries by time; the races' `RACE#`/`LIVE#` queries never see them. Each entry is written once,
conditionally on its key not existing (an entry is never overwritten).
"""
from __future__ import annotations

from typing import Any

from chalicelib.domain.audit import AuditEntry
from chalicelib.storage.aws_errors import all_items, call

_SERVICE = "The races table (audit trail)"
AUDIT_PREFIX = "AUDIT#"


def audit_item(entry: AuditEntry) -> dict[str, Any]:
    return {"pk": {"S": f"EVENT#{entry.event_id}"}, "sk": {"S": f"{AUDIT_PREFIX}{entry.at_ms:013d}#{entry.entry_id}"},
            "action": {"S": entry.action}, "doc": {"S": entry.model_dump_json()}}


class DynamoAuditLog:
    def __init__(self, dynamodb: Any, table: str) -> None:
        self._dynamodb = dynamodb
        self._table = table

    def record(self, entry: AuditEntry) -> None:
        call(self._dynamodb, "put_item", _SERVICE, TableName=self._table, Item=audit_item(entry),
             ConditionExpression="attribute_not_exists(pk)")

    def for_event(self, event_id: str) -> list[AuditEntry]:
        kwargs: dict[str, Any] = {
            "TableName": self._table, "ConsistentRead": True,
            "KeyConditionExpression": "pk = :pk AND begins_with(sk, :prefix)",
            "ExpressionAttributeValues": {":pk": {"S": f"EVENT#{event_id}"}, ":prefix": {"S": AUDIT_PREFIX}}}
        return [AuditEntry.model_validate_json(item["doc"]["S"])
                for item in all_items(self._dynamodb, "query", _SERVICE, **kwargs)]
