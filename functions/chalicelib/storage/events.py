"""DynamoDB adapters for events (table `events`) and the live-race marker they must respect (table `races`).

An event is one item `EVENT#{eventId}` / `META` whose body is the event's JSON (`doc`), plus a `version` that
replacements are conditional on, so two operators editing at once cannot silently overwrite each other.
"""
from __future__ import annotations

from typing import Any

from botocore.exceptions import BotoCoreError, ClientError

from chalicelib.core.errors import Conflict, NotFound
from chalicelib.domain.events import Event
from chalicelib.storage.aws_errors import all_items, translate_common, write_if
from chalicelib.storage.event_logos import logo_key

_SERVICE = "The events table"
_META = "META"


def event_key(event_id: str) -> dict[str, Any]:
    return {"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": _META}}


class DynamoEventStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    def get(self, event_id: str) -> Event | None:
        try:
            reply = self._client.get_item(TableName=self._table, Key=event_key(event_id), ConsistentRead=True)
        except (ClientError, BotoCoreError) as exc:
            raise translate_common(exc, _SERVICE) from exc
        return _event(reply["Item"]) if "Item" in reply else None

    def list(self) -> list[Event]:
        # An occasional staff listing; the table holds only event items.
        return [_event(item) for item in all_items(self._client, "scan", _SERVICE, TableName=self._table,
                                                   FilterExpression="sk = :meta",
                                                   ExpressionAttributeValues={":meta": {"S": _META}})]

    def create(self, event: Event) -> None:
        self._put(event, "attribute_not_exists(pk)", {}, Conflict("An event with this id already exists."))

    def replace(self, event: Event, expected_version: int) -> None:
        self._put(event, "version = :expected", {":expected": {"N": str(expected_version)}},
                  Conflict("Someone else changed this event meanwhile; reload it and try again."))

    def delete(self, event_id: str) -> None:
        if not write_if(self._client, "delete_item", _SERVICE, TableName=self._table, Key=event_key(event_id),
                        ConditionExpression="attribute_exists(pk)"):
            raise NotFound(f"There is no event {event_id}.")
        # Its logo goes with it (a crash in between leaves an image nothing links to, never an event without one).
        write_if(self._client, "delete_item", _SERVICE, TableName=self._table, Key=logo_key(event_id))

    def _put(self, event: Event, condition: str, values: dict[str, Any], on_condition: Exception) -> None:
        item = {**event_key(event.event_id), "eventId": {"S": event.event_id},
                "version": {"N": str(event.version)}, "doc": {"S": event.model_dump_json()}}
        kwargs: dict[str, Any] = {"TableName": self._table, "Item": item, "ConditionExpression": condition}
        if values:
            kwargs["ExpressionAttributeValues"] = values
        if not write_if(self._client, "put_item", _SERVICE, **kwargs):
            raise on_condition


class DynamoLiveRaceProbe:
    """Is a race in progress on a track? The race service keeps `EVENT#{eventId}` / `LIVE#{trackId}` in `races`
    for exactly as long as the race is live, so one GetItem answers."""

    def __init__(self, client: Any, races_table: str) -> None:
        self._client = client
        self._table = races_table

    def has_live_race(self, event_id: str, track_id: str) -> bool:
        key = {"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": f"LIVE#{track_id}"}}
        try:
            reply = self._client.get_item(TableName=self._table, Key=key, ConsistentRead=True,
                                          ProjectionExpression="pk")
        except (ClientError, BotoCoreError) as exc:
            raise translate_common(exc, "The races table") from exc
        return "Item" in reply


def _event(item: dict[str, Any]) -> Event:
    return Event.model_validate_json(item["doc"]["S"])
