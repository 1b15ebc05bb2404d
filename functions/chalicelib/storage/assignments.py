"""DynamoDB adapter for car model assignments (fleet table, `DEVICE#{deviceId}` / `ASSIGNMENT`), and the car directory
assignments read from the devices and events stores.

The item keeps `model_ids` (a list, so a car's report can be made conditional on the model still being assigned),
`models` (JSON) and `progress` (a map of model id → JSON), so a report is one conditional UpdateItem that cannot
overwrite a newer assignment.
"""
from __future__ import annotations

import json
from typing import Any

from chalicelib.core.errors import NotFound
from chalicelib.domain.assignments import AssignedModel, Assignment, AssignmentChanged, ModelProgress
from chalicelib.domain.devices import DeviceKind
from chalicelib.storage.aws_errors import batch_items, call, write_if
from chalicelib.storage.devices import DynamoDeviceStore
from chalicelib.storage.events import DynamoEventStore

_SERVICE = "The fleet table"
_SK = "ASSIGNMENT"


def assignment_key(device_id: str) -> dict[str, Any]:
    return {"pk": {"S": f"DEVICE#{device_id}"}, "sk": {"S": _SK}}


class DynamoAssignmentStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    def get(self, device_id: str) -> Assignment | None:
        reply = self._call("get_item", TableName=self._table, Key=assignment_key(device_id), ConsistentRead=True)
        return _assignment(reply["Item"]) if "Item" in reply else None

    def get_many(self, device_ids: list[str]) -> dict[str, Assignment]:
        found: dict[str, Assignment] = {}
        keys = [assignment_key(device_id) for device_id in dict.fromkeys(device_ids)]
        for item in batch_items(self._client, self._table, keys, _SERVICE, ConsistentRead=True):
            assignment = _assignment(item)
            found[assignment.device_id] = assignment
        return found

    def put(self, assignment: Assignment, *, expected_version: int) -> None:
        condition = ("attribute_not_exists(pk)" if expected_version == 0 else "version = :expected")
        values = {} if expected_version == 0 else {":expected": {"N": str(expected_version)}}
        if not write_if(self._client, "put_item", _SERVICE, TableName=self._table, Item=_item(assignment),
                        ConditionExpression=condition, **({"ExpressionAttributeValues": values} if values else {})):
            raise AssignmentChanged(assignment.device_id)

    def record_progress(self, device_id: str, model_id: str, progress: ModelProgress) -> bool:
        """Store the car's report; False when the model is no longer assigned (nothing written)."""
        return write_if(
            self._client, "update_item", _SERVICE,
            TableName=self._table, Key=assignment_key(device_id),
            UpdateExpression="SET progress.#model = :progress ADD version :one",
            ConditionExpression="attribute_exists(pk) AND contains(model_ids, :model)",
            ExpressionAttributeNames={"#model": model_id},
            ExpressionAttributeValues={":progress": {"S": progress.model_dump_json()}, ":one": {"N": "1"},
                                       ":model": {"S": model_id}})

    def _call(self, operation: str, **kwargs: Any) -> Any:
        return call(self._client, operation, _SERVICE, **kwargs)


def _item(assignment: Assignment) -> dict[str, Any]:
    item: dict[str, Any] = {
        **assignment_key(assignment.device_id),
        "device_id": {"S": assignment.device_id},
        "model_ids": {"L": [{"S": model.model_id} for model in assignment.models]},
        "models": {"S": json.dumps([model.model_dump(mode="json") for model in assignment.models])},
        "progress": {"M": {model_id: {"S": progress.model_dump_json()}
                           for model_id, progress in assignment.progress.items()}},
        "version": {"N": str(assignment.version)},
    }
    if assignment.assigned_by:
        item["assigned_by"] = {"S": assignment.assigned_by}
    if assignment.assigned_at:
        item["assigned_at"] = {"S": assignment.assigned_at}
    return item


def _assignment(item: dict[str, Any]) -> Assignment:
    return Assignment(
        device_id=item["device_id"]["S"],
        models=[AssignedModel.model_validate(model) for model in json.loads(item["models"]["S"])],
        progress={model_id: ModelProgress.model_validate_json(value["S"])
                  for model_id, value in item.get("progress", {}).get("M", {}).items()},
        assigned_by=item.get("assigned_by", {}).get("S"),
        assigned_at=item.get("assigned_at", {}).get("S"),
        version=int(item["version"]["N"]),
    )


class FleetCarDirectory:
    """Cars as the devices registry and events know them (one GetItem each: device, status board, event)."""

    def __init__(self, devices: DynamoDeviceStore, events: DynamoEventStore) -> None:
        self._devices = devices
        self._events = events

    def require_car(self, device_id: str) -> None:
        device = self._devices.get_device(device_id)
        if device is None or device.kind is not DeviceKind.CAR:
            raise NotFound(f"There is no car {device_id!r}.", field="device_id")

    def cars_of_event(self, event_id: str) -> list[str]:
        event = self._events.get(event_id)
        if event is None:
            raise NotFound(f"There is no event {event_id!r}.", field="event_id")
        fleets = {track.fleet_id for track in event.tracks if track.fleet_id}
        board = self._devices.status_board()
        return sorted((entry.device_id for entry in board.values()
                       if entry.kind is DeviceKind.CAR and entry.fleet_id in fleets),
                      key=lambda device_id: (board[device_id].hostname, device_id))

