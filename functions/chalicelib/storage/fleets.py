"""DynamoDB adapter for fleets in the `fleet` table: `FLEET#{fleetId}` / `META` (name, created at/by).

Members are not stored here; a device carries its fleet id (see chalicelib.domain.fleets).
"""
from __future__ import annotations

from typing import Any

from chalicelib.domain.fleets import FleetRecord
from chalicelib.storage.aws_errors import all_items, call

_SERVICE = "The fleet table"


def fleet_key(fleet_id: str) -> dict[str, Any]:
    return {"pk": {"S": f"FLEET#{fleet_id}"}, "sk": {"S": "META"}}


class DynamoFleetStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    def get_fleet(self, fleet_id: str) -> FleetRecord | None:
        item = self._call("get_item", Key=fleet_key(fleet_id), ConsistentRead=True).get("Item")
        return _fleet(item) if item else None

    def fleet_exists(self, fleet_id: str) -> bool:
        return self.get_fleet(fleet_id) is not None

    def list_fleets(self) -> list[FleetRecord]:
        # An occasional staff listing over the (small) fleet table.
        items = all_items(self._client, "scan", _SERVICE, TableName=self._table,
                          FilterExpression="begins_with(pk, :f) AND sk = :meta",
                          ExpressionAttributeValues={":f": {"S": "FLEET#"}, ":meta": {"S": "META"}})
        return [_fleet(item) for item in items]

    def put_fleet(self, fleet: FleetRecord) -> None:
        self._call("put_item", Item={**fleet_key(fleet.fleet_id), "fleetId": {"S": fleet.fleet_id},
                                     "name": {"S": fleet.name}, "createdAtMs": {"N": str(fleet.created_at_ms)},
                                     "createdBy": {"S": fleet.created_by}})

    def delete_fleet(self, fleet_id: str) -> None:
        self._call("delete_item", Key=fleet_key(fleet_id))

    def _call(self, operation: str, **kwargs: Any) -> dict[str, Any]:
        return call(self._client, operation, _SERVICE, TableName=self._table, **kwargs)


def _fleet(item: dict[str, Any]) -> FleetRecord:
    return FleetRecord(fleet_id=item["fleetId"]["S"], name=item["name"]["S"],
                       created_at_ms=int(item["createdAtMs"]["N"]), created_by=item["createdBy"]["S"])
