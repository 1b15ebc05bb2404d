"""DynamoDB adapter for model records (table `models`).

Items:
* the model: pk `OWNER#{sub}`, sk `MODEL#{modelId}`, plus `gsi1pk = MODELS`, `gsi1sk = {uploadedAt}#{modelId}` while
  the model is listed (a soft delete removes both, which takes it out of the operator listing);
* a pointer `MODELID#{modelId}` / `OWNER` holding the owner's sub, so a model can be found by id alone (operators,
  the EventBridge handler, car assignment) with two GetItems instead of a scan.
"""
from __future__ import annotations

import base64
import json
from typing import Any

from chalicelib.core.errors import InvalidInput, NotFound
from chalicelib.domain.racer_models import ModelChanged, ModelPage, ModelRecord, ModelStatus
from chalicelib.storage.aws_errors import all_items, call, write_if

_SERVICE = "The model store"
_LISTING_PK = "MODELS"


def _owner_pk(sub: str) -> str:
    return f"OWNER#{sub}"


def _model_sk(model_id: str) -> str:
    return f"MODEL#{model_id}"


def _pointer_key(model_id: str) -> dict[str, Any]:
    return {"pk": {"S": f"MODELID#{model_id}"}, "sk": {"S": "OWNER"}}


class DynamoModelStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    # -- writes ----------------------------------------------------------------------------------------------------

    def create(self, record: ModelRecord) -> None:
        item = _to_item(record)
        pointer = {**_pointer_key(record.model_id), "owner_sub": {"S": record.owner_sub}}
        self._call("transact_write_items", TransactItems=[
            {"Put": {"TableName": self._table, "Item": item, "ConditionExpression": "attribute_not_exists(pk)"}},
            {"Put": {"TableName": self._table, "Item": pointer, "ConditionExpression": "attribute_not_exists(pk)"}},
        ])

    def replace(self, record: ModelRecord, *, expected_status: ModelStatus,
                result_as_in: ModelRecord | None = None) -> None:
        """Write `record` only if the stored status is still `expected_status` and, given `result_as_in`, the stored
        scrutineering result is still the one that record holds (raises ModelChanged otherwise)."""
        condition = "#status = :expected"
        names = {"#status": "status"}
        values = {":expected": {"S": expected_status.value}}
        if result_as_in is not None:
            names["#result"] = "scrutineer_result"
            if result_as_in.scrutineer_result is None:
                condition += " AND attribute_not_exists(#result)"
            else:  # the stored text is this exact dump (_to_item), so equal text is the same result
                condition += " AND #result = :result"
                values[":result"] = {"S": result_as_in.scrutineer_result.model_dump_json()}
        if not write_if(self._client, "put_item", _SERVICE, TableName=self._table, Item=_to_item(record),
                        ConditionExpression=condition, ExpressionAttributeNames=names,
                        ExpressionAttributeValues=values):
            raise ModelChanged(record.model_id)

    # -- reads -----------------------------------------------------------------------------------------------------

    def get(self, owner_sub: str, model_id: str) -> ModelRecord | None:
        reply = self._call("get_item", TableName=self._table, ConsistentRead=True,
                           Key={"pk": {"S": _owner_pk(owner_sub)}, "sk": {"S": _model_sk(model_id)}})
        return _from_item(reply["Item"]) if "Item" in reply else None

    def owner_of(self, model_id: str) -> str | None:
        reply = self._call("get_item", TableName=self._table, Key=_pointer_key(model_id), ConsistentRead=True)
        return reply["Item"]["owner_sub"]["S"] if "Item" in reply else None

    def get_by_id(self, model_id: str) -> ModelRecord | None:
        owner = self.owner_of(model_id)
        return self.get(owner, model_id) if owner is not None else None

    def list_owner(self, owner_sub: str, *, limit: int, next_token: str | None,
                   include_deleted: bool = False) -> ModelPage:
        """The owner's models (not DELETED unless `include_deleted`), newest first: model ids sort by creation
        time. Account deletion needs the soft-deleted ones too: they still hold the archive and the racer's name."""
        pk = _owner_pk(owner_sub)
        query: dict[str, Any] = dict(
            TableName=self._table, KeyConditionExpression="pk = :pk AND begins_with(sk, :model)",
            ExpressionAttributeValues={":pk": {"S": pk}, ":model": {"S": "MODEL#"}},
            ScanIndexForward=False, Limit=limit)
        if not include_deleted:
            query.update(FilterExpression="#status <> :deleted", ExpressionAttributeNames={"#status": "status"})
            query["ExpressionAttributeValues"][":deleted"] = {"S": ModelStatus.DELETED.value}
        return self._page(query, next_token, required={"pk": pk}, key_names=("pk", "sk"))

    def list_all(self, *, limit: int, next_token: str | None) -> ModelPage:
        query: dict[str, Any] = dict(
            TableName=self._table, IndexName="gsi1", KeyConditionExpression="gsi1pk = :listing",
            ExpressionAttributeValues={":listing": {"S": _LISTING_PK}}, ScanIndexForward=False, Limit=limit)
        return self._page(query, next_token, required={"gsi1pk": _LISTING_PK},
                          key_names=("pk", "sk", "gsi1pk", "gsi1sk"))

    def find_available_by_md5(self, owner_sub: str, model_md5: str) -> list[ModelRecord]:
        query: dict[str, Any] = dict(
            TableName=self._table, KeyConditionExpression="pk = :pk AND begins_with(sk, :model)",
            FilterExpression="#status = :available AND model_md5 = :md5",
            ExpressionAttributeNames={"#status": "status"},
            ExpressionAttributeValues={":pk": {"S": _owner_pk(owner_sub)}, ":model": {"S": "MODEL#"},
                                       ":available": {"S": ModelStatus.AVAILABLE.value}, ":md5": {"S": model_md5}})
        found = [_from_item(item) for item in all_items(self._client, "query", _SERVICE, **query)]
        return sorted(found, key=lambda record: record.model_id)

    # -- helpers ---------------------------------------------------------------------------------------------------

    def _page(self, query: dict[str, Any], next_token: str | None, *, required: dict[str, str],
              key_names: tuple[str, ...]) -> ModelPage:
        if next_token:
            query["ExclusiveStartKey"] = decode_token(next_token, required=required, key_names=key_names)
        reply = self._call("query", **query)
        last = reply.get("LastEvaluatedKey")
        return ModelPage(models=[_from_item(item) for item in reply.get("Items", [])],
                         next_token=encode_token(last) if last else None)

    def _call(self, operation: str, **kwargs: Any) -> Any:
        return call(self._client, operation, _SERVICE, **kwargs)


def encode_token(key: dict[str, Any]) -> str:
    plain = {name: value["S"] for name, value in key.items()}
    return base64.urlsafe_b64encode(json.dumps(plain, sort_keys=True).encode()).decode().rstrip("=")


def decode_token(token: str, *, required: dict[str, str], key_names: tuple[str, ...]) -> dict[str, Any]:
    """The DynamoDB start key inside an opaque token, refusing tokens we did not issue for this very listing."""
    try:
        plain = json.loads(base64.urlsafe_b64decode(token + "=" * (-len(token) % 4)))
    except ValueError:
        plain = None
    valid = (isinstance(plain, dict) and set(plain) == set(key_names)
             and all(isinstance(value, str) and len(value) <= 512 for value in plain.values())
             and all(plain.get(name) == value for name, value in required.items()))
    if not valid:
        raise InvalidInput("This page token is not valid here; start again from the first page.", field="next")
    return {name: {"S": value} for name, value in plain.items()}


_FACT_FIELDS = ("reason", "model_kind", "model_md5", "metadata_md5", "archive_md5", "action_space_type",
                "training_algorithm", "s3_key", "converted_key", "converted_md5", "scrutiny", "scrutiny_reason",
                "scrutiny_detail", "conversion_max_diff", "scrutineer_state", "scrutineer_clip_key", "check_started_at")


def _to_item(record: ModelRecord) -> dict[str, Any]:
    item: dict[str, Any] = {
        "pk": {"S": _owner_pk(record.owner_sub)},
        "sk": {"S": _model_sk(record.model_id)},
        "model_id": {"S": record.model_id},
        "owner_sub": {"S": record.owner_sub},
        "owner_username": {"S": record.owner_username},
        "name": {"S": record.name},
        "status": {"S": record.status.value},
        "uploaded_at": {"S": record.uploaded_at},
        "updated_at": {"S": record.updated_at},
        "upload_key": {"S": record.upload_key},
        "size_bytes": {"N": str(record.size_bytes)},
        "sensor": {"L": [{"S": sensor} for sensor in record.sensor]},
    }
    if record.check_attempts:
        item["check_attempts"] = {"N": str(record.check_attempts)}
    for name in _FACT_FIELDS:
        value = getattr(record, name)
        if value is not None:
            item[name] = {"S": str(value)}
    if record.scrutineer_result is not None:
        item["scrutineer_result"] = {"S": record.scrutineer_result.model_dump_json()}
    if record.duplicate_of is not None:
        item["duplicate_of"] = {"M": {"model_id": {"S": record.duplicate_of.model_id},
                                      "name": {"S": record.duplicate_of.name}}}
    if record.status is not ModelStatus.DELETED:
        item["gsi1pk"] = {"S": _LISTING_PK}
        item["gsi1sk"] = {"S": f"{record.uploaded_at}#{record.model_id}"}
    return item


def _from_item(item: dict[str, Any]) -> ModelRecord:
    values: dict[str, Any] = {
        "model_id": item["model_id"]["S"], "owner_sub": item["owner_sub"]["S"],
        "owner_username": item["owner_username"]["S"], "name": item["name"]["S"], "status": item["status"]["S"],
        "uploaded_at": item["uploaded_at"]["S"], "updated_at": item["updated_at"]["S"],
        "upload_key": item["upload_key"]["S"], "size_bytes": int(item["size_bytes"]["N"]),
        "sensor": [entry["S"] for entry in item.get("sensor", {}).get("L", [])],
        "check_attempts": int(item.get("check_attempts", {}).get("N", "0")),
    }
    for name in _FACT_FIELDS:
        if name in item:
            values[name] = item[name]["S"]
    if "scrutineer_result" in item:
        values["scrutineer_result"] = json.loads(item["scrutineer_result"]["S"])
    if "duplicate_of" in item:
        duplicate = item["duplicate_of"]["M"]
        values["duplicate_of"] = {"model_id": duplicate["model_id"]["S"], "name": duplicate["name"]["S"]}
    return ModelRecord.model_validate(values)


class EventTrackTypes:
    """The track type an event races on (what scrutineering drives on), read from the events table."""

    def __init__(self, store: Any) -> None:
        self._store = store

    def track_type_of(self, event_id: str) -> str:
        event = self._store.get(event_id)
        if event is None:
            raise NotFound(f"There is no event {event_id[:64]!r}.", field="event_id")
        return event.race_config.track_type.value

