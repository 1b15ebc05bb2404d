"""DynamoDB adapter for the `races` table: race items, the live-race pointer of each track, and the stored outcomes
of timing-strip posts (idempotency).

| item | pk | sk |
|---|---|---|
| race (the whole `RaceRecord` as JSON in `doc`, plus `track_id`, `racer_sub`, `status`, `version` to filter on) | `EVENT#{eventId}` | `RACE#{raceId}` |
| live race of a track (`race_id`, `racer`) | `EVENT#{eventId}` | `LIVE#{trackId}` |
| stored strip outcome (`outcome` JSON) | `IDEMPOTENCY#{deviceId}` | `{key}` |
| publish intent: a racer's board row still to rebuild (`event_id`, `track_id`, `racer_sub`, `race_id`, `token`) | `PUBLISH` | `{eventId}#{trackId}#{racerSub}` |

The race body is a JSON string rather than a DynamoDB map: no float/Decimal round trips, and one attribute to parse.
Every race write is conditional on the race's `version` (optimistic concurrency); a lost race raises `StaleRace` so
the service can reload and retry. Writes that must happen together (race + live pointer, race + stored outcome) are
one transaction, so a retried strip post can never produce a second lap.

Every race write also puts the racer's publish intent in the same transaction. The board is derived state: the
service deletes the intent (only if its token is still the one it wrote) after the board and overlay are rebuilt,
so a crash between the race write and the board write leaves the intent behind for whoever comes next
(`pending_publishes`: a retry, the next race write, or the app's sweeper) to finish. All intents share one
partition, so finding them is one Query, empty almost always.
"""
from __future__ import annotations

import time
from typing import Any

from chalicelib.core.errors import Conflict
from chalicelib.domain.race_writes import StaleRace
from chalicelib.domain.races import PublishIntent, RaceRecord
from chalicelib.storage.aws_errors import all_items, call, write_if

_SERVICE = "The races table"


def _s(value: str) -> dict[str, str]:
    return {"S": value}


def _n(value: int) -> dict[str, str]:
    return {"N": str(value)}


def race_key(event_id: str, race_id: str) -> dict[str, Any]:
    return {"pk": _s(f"EVENT#{event_id}"), "sk": _s(f"RACE#{race_id}")}


def live_key(event_id: str, track_id: str) -> dict[str, Any]:
    return {"pk": _s(f"EVENT#{event_id}"), "sk": _s(f"LIVE#{track_id}")}


def outcome_key(device_id: str, key: str) -> dict[str, Any]:
    return {"pk": _s(f"IDEMPOTENCY#{device_id}"), "sk": _s(key)}


PUBLISH_PK = "PUBLISH"


def intent_key(event_id: str, track_id: str, racer_sub: str) -> dict[str, Any]:
    return {"pk": _s(PUBLISH_PK), "sk": _s(f"{event_id}#{track_id}#{racer_sub}")}


def _wall_ms() -> int:
    return time.time_ns() // 1_000_000


def _intent_put(intent: PublishIntent, table: str) -> dict[str, Any]:
    item = {**intent_key(intent.event_id, intent.track_id, intent.racer_sub), "event_id": _s(intent.event_id),
            "track_id": _s(intent.track_id), "racer_sub": _s(intent.racer_sub), "racer": _s(intent.racer_username),
            "race_id": _s(intent.race_id), "token": _s(intent.token), "at_ms": _n(_wall_ms())}
    return {"Put": {"TableName": table, "Item": item}}


def _intent(item: dict[str, Any]) -> PublishIntent:
    return PublishIntent(event_id=item["event_id"]["S"], track_id=item["track_id"]["S"],
                         racer_sub=item["racer_sub"]["S"], racer_username=item.get("racer", {}).get("S", ""),
                         race_id=item["race_id"]["S"], token=item["token"]["S"])


def _race_item(record: RaceRecord) -> dict[str, Any]:
    race = record.race
    return {**race_key(race.event_id, race.race_id), "race_id": _s(race.race_id), "event_id": _s(race.event_id),
            "track_id": _s(race.track_id), "racer_sub": _s(race.racer.sub), "status": _s(race.status.value),
            "version": _n(race.version), "created_at_ms": _n(race.created_at_ms), "doc": _s(record.model_dump_json())}


def _record(item: dict[str, Any]) -> RaceRecord:
    return RaceRecord.model_validate_json(item["doc"]["S"])


class DynamoRaceStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    # --- reads ---------------------------------------------------------------------------------------------------

    def get(self, event_id: str, race_id: str) -> RaceRecord | None:
        item = self._call("get_item", TableName=self._table, Key=race_key(event_id, race_id),
                          ConsistentRead=True).get("Item")
        return _record(item) if item else None

    def live_race_id(self, event_id: str, track_id: str) -> str | None:
        item = self._call("get_item", TableName=self._table, Key=live_key(event_id, track_id),
                          ConsistentRead=True).get("Item")
        return item["race_id"]["S"] if item else None

    def live_racer(self, event_id: str, track_id: str) -> str | None:
        item = self._call("get_item", TableName=self._table, Key=live_key(event_id, track_id),
                          ConsistentRead=True).get("Item")
        return item.get("racer", {}).get("S") if item else None

    def list_event(self, event_id: str, *, track_id: str | None = None, racer_sub: str | None = None,
                   ) -> list[RaceRecord]:
        # An occasional listing (race admin, recompute, max-runs check): a Query on the event's partition.
        filters, values = [], {":pk": _s(f"EVENT#{event_id}"), ":prefix": _s("RACE#")}
        if track_id is not None:
            filters.append("track_id = :track")
            values[":track"] = _s(track_id)
        if racer_sub is not None:
            filters.append("racer_sub = :sub")
            values[":sub"] = _s(racer_sub)
        kwargs: dict[str, Any] = {"TableName": self._table, "ConsistentRead": True,
                                  "KeyConditionExpression": "pk = :pk AND begins_with(sk, :prefix)",
                                  "ExpressionAttributeValues": values}
        if filters:
            kwargs["FilterExpression"] = " AND ".join(filters)
        return [_record(item) for item in all_items(self._client, "query", _SERVICE, **kwargs)]

    def list_racer(self, racer_sub: str) -> list[RaceRecord]:
        """Every race of one racer, all events (their own "my races" page; occasional, so a filtered Scan)."""
        kwargs = {"TableName": self._table, "FilterExpression": "racer_sub = :sub AND begins_with(sk, :prefix)",
                  "ExpressionAttributeValues": {":sub": _s(racer_sub), ":prefix": _s("RACE#")}}
        return [_record(item) for item in all_items(self._client, "scan", _SERVICE, **kwargs)]

    def get_outcome(self, device_id: str, key: str) -> str | None:
        item = self._call("get_item", TableName=self._table, Key=outcome_key(device_id, key),
                          ConsistentRead=True).get("Item")
        return item["outcome"]["S"] if item else None

    # --- writes --------------------------------------------------------------------------------------------------

    def create_live(self, record: RaceRecord) -> None:
        """Store a new race and make it the live race of its track, or raise Conflict naming the race in the way."""
        race = record.race
        pointer = {**live_key(race.event_id, race.track_id), "race_id": _s(race.race_id),
                   "racer": _s(race.racer.username)}
        created = write_if(self._client, "transact_write_items", _SERVICE, TransactItems=[
            {"Put": {"TableName": self._table, "Item": _race_item(record),
                     "ConditionExpression": "attribute_not_exists(pk)"}},
            {"Put": {"TableName": self._table, "Item": pointer,
                     "ConditionExpression": "attribute_not_exists(pk)"}},
            _intent_put(PublishIntent.of(race), self._table),
        ])
        if not created:
            racer = self.live_racer(race.event_id, race.track_id)
            raise Conflict(f"Track {race.track_id} already has a live race"
                           f"{f' ({racer})' if racer else ''}; submit or discard it first.", field="track_id")

    def save(self, record: RaceRecord, expected_version: int) -> None:
        """Save a changed race (conditional on its version) together with its publish intent."""
        self._transact([
            {"Put": {"TableName": self._table, "Item": _race_item(record),
                     "ConditionExpression": "version = :expected",
                     "ExpressionAttributeValues": {":expected": _n(expected_version)}}},
            _intent_put(PublishIntent.of(record.race), self._table),
        ], record.race.race_id)

    def finalise(self, record: RaceRecord, expected_version: int) -> None:
        """Save a submitted/discarded race and clear its track's live pointer, together."""
        race = record.race
        self._transact([
            {"Put": {"TableName": self._table, "Item": _race_item(record),
                     "ConditionExpression": "version = :expected",
                     "ExpressionAttributeValues": {":expected": _n(expected_version)}}},
            {"Delete": {"TableName": self._table, "Key": live_key(race.event_id, race.track_id),
                        "ConditionExpression": "race_id = :rid",
                        "ExpressionAttributeValues": {":rid": _s(race.race_id)}}},
            _intent_put(PublishIntent.of(race), self._table),
        ], race.race_id)

    def save_with_outcome(self, record: RaceRecord | None, expected_version: int | None, device_id: str, key: str,
                          outcome_json: str) -> bool:
        """Store a strip outcome under its key, together with the race it changed (if any).

        Returns False when the key was already stored (a concurrent retry won): the caller replays the stored one.
        Raises StaleRace when the race changed meanwhile (the caller reloads and decides again).
        """
        items: list[dict[str, Any]] = [{"Put": {
            "TableName": self._table, "Item": {**outcome_key(device_id, key), "outcome": _s(outcome_json)},
            "ConditionExpression": "attribute_not_exists(pk)"}}]
        if record is not None and expected_version is not None:
            items.append({"Put": {"TableName": self._table, "Item": _race_item(record),
                                  "ConditionExpression": "version = :expected",
                                  "ExpressionAttributeValues": {":expected": _n(expected_version)}}})
            items.append(_intent_put(PublishIntent.of(record.race), self._table))
        if write_if(self._client, "transact_write_items", _SERVICE, TransactItems=items):
            return True
        if self.get_outcome(device_id, key) is not None:
            return False
        raise StaleRace(record.race.race_id if record else key)

    def delete(self, record: RaceRecord) -> None:
        """Delete a finished race together with a publish intent for its racer's row (which it no longer counts in)."""
        race = record.race
        self._transact([
            {"Delete": {"TableName": self._table, "Key": race_key(race.event_id, race.race_id)}},
            _intent_put(PublishIntent.of(race, deleted=True), self._table),
        ], race.race_id)

    # --- publish intents -----------------------------------------------------------------------------------------

    def pending_publishes(self, older_than_ms: int = 0) -> list[PublishIntent]:
        """Intents still stored, written at least `older_than_ms` ago (by this adapter's wall clock: younger ones
        usually belong to a request that is publishing right now)."""
        kwargs = {"TableName": self._table, "ConsistentRead": True, "KeyConditionExpression": "pk = :pk",
                  "ExpressionAttributeValues": {":pk": _s(PUBLISH_PK)}}
        cutoff = _wall_ms() - older_than_ms
        return [_intent(item) for item in all_items(self._client, "query", _SERVICE, **kwargs)
                if older_than_ms <= 0 or int(item.get("at_ms", {"N": "0"})["N"]) <= cutoff]

    def complete_publish(self, intent: PublishIntent) -> None:
        """Drop the intent once its board row is rebuilt; a newer write's intent (another token) stays."""
        write_if(self._client, "delete_item", _SERVICE, TableName=self._table,
                 Key=intent_key(intent.event_id, intent.track_id, intent.racer_sub),
                 ConditionExpression="#token = :token", ExpressionAttributeNames={"#token": "token"},
                 ExpressionAttributeValues={":token": _s(intent.token)})

    # --- plumbing ------------------------------------------------------------------------------------------------

    def _transact(self, items: list[dict[str, Any]], race_id: str) -> None:
        if not write_if(self._client, "transact_write_items", _SERVICE, TransactItems=items):
            raise StaleRace(race_id)

    def _call(self, operation: str, **kwargs: Any) -> dict[str, Any]:
        return call(self._client, operation, _SERVICE, **kwargs)
