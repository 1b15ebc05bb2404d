"""DynamoDB adapter for devices in the `fleet` table: registry, activation codes, the status board and commands.

Keys (docs/data-model.md, table `fleet`):
  device            DEVICE#{deviceId} / META                 registry item with the secret's SHA-256
  activation code   ACTIVATION#{sha256(code)} / META          marked redeemed (device id, attempt hash)
  command           DEVICE#{deviceId} / COMMAND#{ms}#{rand}   public id "{ms}-{rand}"
  status board      STATUS / ALL                              map `devices` of deviceId -> status entry
"""
from __future__ import annotations

import json
from decimal import Decimal
from typing import Any

from boto3.dynamodb.types import TypeDeserializer, TypeSerializer

from chalicelib.core.errors import Conflict
from chalicelib.domain.activation import ActivationExchange, ActivationRecord
from chalicelib.domain.devices import (
    CarVideoSettings,
    Command,
    CommandAck,
    CommandStatus,
    DeviceRecord,
    StatusEntry,
    Telemetry,
)
from chalicelib.storage.aws_errors import all_items, call, write_if

_SERVICE = "The fleet table"
_META = "META"
_STATUS_KEY = {"pk": {"S": "STATUS"}, "sk": {"S": "ALL"}}
_serializer, _deserializer = TypeSerializer(), TypeDeserializer()


def device_key(device_id: str) -> dict[str, Any]:
    return {"pk": {"S": f"DEVICE#{device_id}"}, "sk": {"S": _META}}


def activation_key(code_hash: str) -> dict[str, Any]:
    return {"pk": {"S": f"ACTIVATION#{code_hash}"}, "sk": {"S": _META}}


def command_key(device_id: str, command_id: str) -> dict[str, Any]:
    created_ms, _, rand = command_id.partition("-")
    return {"pk": {"S": f"DEVICE#{device_id}"}, "sk": {"S": f"COMMAND#{created_ms}#{rand}"}}


class DynamoDeviceStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    # --- registry ---
    def get_device(self, device_id: str) -> DeviceRecord | None:
        item = self._call("get_item", Key=device_key(device_id), ConsistentRead=True).get("Item")
        return _device(item) if item else None

    def delete_device(self, device_id: str) -> None:
        self._call("delete_item", Key=device_key(device_id))
        self._remove_status_entry(device_id)

    def set_fleet(self, device_id: str, fleet_id: str | None) -> None:
        value = {"S": fleet_id} if fleet_id else {"NULL": True}
        if not self._write_if("update_item", Key=device_key(device_id), UpdateExpression="SET fleetId = :f",
                              ConditionExpression="attribute_exists(pk)", ExpressionAttributeValues={":f": value}):
            return  # deregistered meanwhile: nothing to move
        if not self._update_status_entry(device_id, "SET devices.#d.fleet_id = :f", {":f": value}):
            record = self.get_device(device_id)
            if record:
                self.put_status_entry(StatusEntry.for_device(record))

    def set_video(self, device_id: str, video: CarVideoSettings) -> None:
        value = _attr(video.model_dump(mode="json"))
        if not self._write_if("update_item", Key=device_key(device_id), UpdateExpression="SET video = :v",
                              ConditionExpression="attribute_exists(pk)", ExpressionAttributeValues={":v": value}):
            return  # deregistered meanwhile
        if not self._update_status_entry(device_id, "SET devices.#d.video = :v", {":v": value}):
            record = self.get_device(device_id)
            if record:
                self.put_status_entry(StatusEntry.for_device(record))

    def replace_secret_hash(self, device_id: str, secret_hash: str) -> bool:
        return self._write_if("update_item", Key=device_key(device_id), UpdateExpression="SET secretHash = :h",
                              ConditionExpression="attribute_exists(pk)",
                              ExpressionAttributeValues={":h": {"S": secret_hash}})

    # --- activation codes ---
    def put_activation(self, record: ActivationRecord) -> None:
        item = {**activation_key(record.code_hash), "fleetId": {"S": record.fleet_id},
                "hostname": {"S": record.hostname}, "hostnameKey": {"S": record.hostname.lower()},
                "deviceKind": {"S": record.device_kind.value}, "expiresAtMs": {"N": str(record.expires_at_ms)},
                "createdAtMs": {"N": str(record.created_at_ms)}, "createdBy": {"S": record.created_by}}
        self._call("put_item", Item=item)

    def get_activation(self, code_hash: str) -> ActivationRecord | None:
        item = self._call("get_item", Key=activation_key(code_hash), ConsistentRead=True).get("Item")
        if not item:
            return None
        return ActivationRecord(code_hash=code_hash, fleet_id=item["fleetId"]["S"], hostname=item["hostname"]["S"],
                                device_kind=item["deviceKind"]["S"], expires_at_ms=int(item["expiresAtMs"]["N"]),
                                created_at_ms=int(item["createdAtMs"]["N"]), created_by=item["createdBy"]["S"],
                                redeemed_device_id=item.get("redeemedDeviceId", {}).get("S"),
                                redeemed_attempt_hash=item.get("redeemedAttemptHash", {}).get("S"))

    def redeem(self, code_hash: str, exchange: ActivationExchange, now_ms: int, device: DeviceRecord,
               line: StatusEntry, attempt_hash: str | None) -> bool:
        """Mark the code redeemed, register the device and put its status line, atomically; False when the code is
        gone, already redeemed, expired or mismatched. The code item stays (marked) so a retry of the same attempt
        can resume (domain/activation.py)."""
        self._ensure_status_item()
        marks, values = "SET redeemedDeviceId = :d, redeemedAtMs = :now", {
            ":now": {"N": str(now_ms)}, ":kind": {"S": exchange.device_kind.value},
            ":host": {"S": exchange.hostname.lower()}, ":d": {"S": device.device_id}}
        if attempt_hash:
            marks, values[":a"] = marks + ", redeemedAttemptHash = :a", {"S": attempt_hash}
        mark_code = {"Update": {
            "TableName": self._table, "Key": activation_key(code_hash), "UpdateExpression": marks,
            "ConditionExpression": "attribute_exists(pk) AND attribute_not_exists(redeemedDeviceId) "
                                   "AND expiresAtMs > :now AND deviceKind = :kind AND hostnameKey = :host",
            "ExpressionAttributeValues": values}}
        register = {"Put": {"TableName": self._table, "Item": _device_item(device),
                            "ConditionExpression": "attribute_not_exists(pk)"}}
        board_line = {"Update": {"TableName": self._table, "Key": _STATUS_KEY,
                                 "UpdateExpression": "SET devices.#d = :e",
                                 "ExpressionAttributeNames": {"#d": device.device_id},
                                 "ExpressionAttributeValues": {":e": _attr(line.model_dump(mode="json"))}}}
        return write_if(self._client, "transact_write_items", _SERVICE,
                        TransactItems=[mark_code, register, board_line])

    # --- status board ---
    def status_board(self) -> dict[str, StatusEntry]:
        item = self._call("get_item", Key=_STATUS_KEY, ConsistentRead=True).get("Item")
        if not item or "devices" not in item:
            return {}
        entries = _plain(_deserializer.deserialize(item["devices"]))
        return {device_id: StatusEntry.model_validate(entry) for device_id, entry in entries.items()}

    def put_status_entry(self, entry: StatusEntry) -> None:
        self._ensure_status_item()
        self._call("update_item", Key=_STATUS_KEY, UpdateExpression="SET devices.#d = :e",
                   ExpressionAttributeNames={"#d": entry.device_id},
                   ExpressionAttributeValues={":e": _attr(entry.model_dump(mode="json"))})

    def record_heartbeat(self, device_id: str, now_ms: int, telemetry: Telemetry) -> bool:
        """Stamp one device's line in place (other devices' lines are untouched); False if it has no line."""
        return self._update_status_entry(
            device_id, "SET devices.#d.last_seen_ms = :now, devices.#d.telemetry = :t",
            {":now": {"N": str(now_ms)}, ":t": _attr(telemetry.model_dump(mode="json"))})

    def _update_status_entry(self, device_id: str, expression: str, values: dict[str, Any]) -> bool:
        return self._write_if("update_item", Key=_STATUS_KEY, UpdateExpression=expression,
                              ConditionExpression="attribute_exists(devices.#d)",
                              ExpressionAttributeNames={"#d": device_id}, ExpressionAttributeValues=values)

    def _remove_status_entry(self, device_id: str) -> None:
        self._write_if("update_item", Key=_STATUS_KEY, UpdateExpression="REMOVE devices.#d",
                       ConditionExpression="attribute_exists(devices.#d)", ExpressionAttributeNames={"#d": device_id})

    def _ensure_status_item(self) -> None:
        # SET devices.#d needs the `devices` map to exist; create it once, never overwriting a live board.
        self._write_if("put_item", Item={**_STATUS_KEY, "devices": {"M": {}}},
                       ConditionExpression="attribute_not_exists(pk)")

    # --- commands ---
    def put_command(self, command: Command) -> None:
        item = {**command_key(command.device_id, command.command_id), "doc": {"S": command.model_dump_json()},
                "status": {"S": command.status.value}}
        if not self._write_if("put_item", Item=item, ConditionExpression="attribute_not_exists(pk)"):
            raise Conflict(f"Command {command.command_id} already exists.")

    def commands(self, device_id: str, *, pending_only: bool = False) -> list[Command]:
        kwargs: dict[str, Any] = {
            "KeyConditionExpression": "pk = :pk AND begins_with(sk, :c)",
            "ExpressionAttributeValues": {":pk": {"S": f"DEVICE#{device_id}"}, ":c": {"S": "COMMAND#"}}}
        if pending_only:
            kwargs["FilterExpression"] = "#s = :pending"
            kwargs["ExpressionAttributeNames"] = {"#s": "status"}
            kwargs["ExpressionAttributeValues"][":pending"] = {"S": CommandStatus.PENDING.value}
        return [Command.model_validate_json(item["doc"]["S"]) for item in all_items(
            self._client, "query", _SERVICE, TableName=self._table, ConsistentRead=True, **kwargs)]

    def ack_command(self, device_id: str, command_id: str, ack: CommandAck, now_ms: int) -> Command | None:
        key = command_key(device_id, command_id)
        item = self._call("get_item", Key=key, ConsistentRead=True).get("Item")
        if not item:
            return None
        acked = Command.model_validate_json(item["doc"]["S"]).model_copy(
            update={"status": ack.result, "message": ack.message, "acked_at_ms": now_ms})
        # Only a pending command can be acknowledged, and only once.
        if not self._write_if("put_item",
                              Item={**key, "doc": {"S": acked.model_dump_json()}, "status": {"S": ack.result.value}},
                              ConditionExpression="#s = :pending", ExpressionAttributeNames={"#s": "status"},
                              ExpressionAttributeValues={":pending": {"S": CommandStatus.PENDING.value}}):
            raise Conflict(f"Command {command_id} was already acknowledged.")
        return acked

    # --- plumbing ---
    def _call(self, operation: str, **kwargs: Any) -> dict[str, Any]:
        return call(self._client, operation, _SERVICE, TableName=self._table, **kwargs)

    def _write_if(self, operation: str, **kwargs: Any) -> bool:
        return write_if(self._client, operation, _SERVICE, TableName=self._table, **kwargs)


def _device_item(device: DeviceRecord) -> dict[str, Any]:
    item = {**device_key(device.device_id), "deviceId": {"S": device.device_id}, "kind": {"S": device.kind.value},
            "hostname": {"S": device.hostname}, "secretHash": {"S": device.secret_hash},
            "registeredAtMs": {"N": str(device.registered_at_ms)}, "activatedBy": {"S": device.activated_by},
            "fleetId": {"S": device.fleet_id} if device.fleet_id else {"NULL": True}}
    return item


def _device(item: dict[str, Any]) -> DeviceRecord:
    fleet = item.get("fleetId", {})
    return DeviceRecord(device_id=item["deviceId"]["S"], kind=item["kind"]["S"], hostname=item["hostname"]["S"],
                        fleet_id=fleet.get("S"), secret_hash=item["secretHash"]["S"],
                        registered_at_ms=int(item["registeredAtMs"]["N"]), activated_by=item["activatedBy"]["S"],
                        video=_plain(_deserializer.deserialize(item["video"])) if "video" in item else None)


def _attr(value: Any) -> dict[str, Any]:
    # DynamoDB numbers must be Decimals; JSON round-trip turns floats into exact decimal text first.
    return _serializer.serialize(json.loads(json.dumps(value), parse_float=Decimal))


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, Decimal):
        return int(value) if value == value.to_integral_value() else float(value)
    return value
