"""DynamoDB adapter for the virtual league (table `league`).

Items:
* `TRACK#{track}` / `BOARD`: the materialised board, `entries` = JSON map racer → BoardEntry (each racer's latest
  submission summary) and `version`; the public pull is this one GetItem (moto's Query scans the whole table);
* `TRACK#{track}` / `RACER#{racer}#SUB#{submittedAt}`: every submission in full (hyperparameters, trials), kept as
  history; the hyperparameters "on demand" are one GetItem of the latest one.

* `TRACK#{track}` / `POLICY`: what the organiser does with self-reported entries (`self_reported`);
* `LEAGUE#TRACKS` / `TRACK#{name}`: a track staff registered (`length_m`), beside drem's own set;
* `EVIDENCE#{digest}` / `OWNER`: which racer first pushed an evaluation's log content (`racer`).

A push writes all three in one transaction, the board guarded by its version (optimistic: the loser re-reads and
retries) and the evidence claim by its owner, so the board never names a submission that was not stored, and two
racers pushing the same logs at once cannot both be ranked.
"""
from __future__ import annotations

import json
from typing import Any

from chalicelib.core.errors import Conflict
from chalicelib.domain.league import BoardEntry, EvidenceTaken, LeaguePolicy, Submission
from chalicelib.domain.league_tracks import RegisteredTrack
from chalicelib.storage.aws_errors import all_items, call, write_if

_SERVICE = "The league store"
_BOARD_SK = "BOARD"
_ATTEMPTS = 6


def _pk(track: str) -> dict[str, str]:
    return {"S": f"TRACK#{track}"}


def _evidence_key(digest: str) -> dict[str, Any]:
    return {"pk": {"S": f"EVIDENCE#{digest}"}, "sk": {"S": "OWNER"}}


def _history_sk(racer: str, submission_id: str) -> dict[str, str]:
    return {"S": f"RACER#{racer}#SUB#{submission_id}"}


class DynamoLeagueStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    def board(self, track: str) -> dict[str, BoardEntry]:
        return self._board(track)[0]

    def record(self, submission: Submission) -> None:
        history = {"pk": _pk(submission.track), "sk": _history_sk(submission.racer, submission.submission_id),
                   "body": {"S": submission.model_dump_json()}}
        digest = submission.evidence_digest or ""
        claim = {"Put": {"TableName": self._table,
                         "Item": {**_evidence_key(digest), "racer": {"S": submission.racer}},
                         "ConditionExpression": "attribute_not_exists(pk) OR racer = :racer",
                         "ExpressionAttributeValues": {":racer": {"S": submission.racer}}}}
        for _ in range(_ATTEMPTS):
            entries, version = self._board(submission.track)
            entries[submission.racer] = submission.entry()
            board_put = self._board_put(submission.track, entries, version)
            if write_if(self._client, "transact_write_items", _SERVICE, TransactItems=[
                    {"Put": {"TableName": self._table, "Item": history,
                             "ConditionExpression": "attribute_not_exists(pk)"}},
                    board_put, claim]):
                return
            owner = self.evidence_owner(digest)
            if owner is not None and owner != submission.racer:
                raise EvidenceTaken(owner)  # another racer's push of the same logs won the race
        raise Conflict("The league board is busy; push again in a moment.")

    def replace(self, submission: Submission) -> bool:
        """The submission rewritten (drem's re-drive), and the board entry while it is still the racer's latest."""
        key = {"pk": _pk(submission.track), "sk": _history_sk(submission.racer, submission.submission_id)}
        for _ in range(_ATTEMPTS):
            entries, version = self._board(submission.track)
            items: list[dict[str, Any]] = [{"Put": {
                "TableName": self._table, "Item": {**key, "body": {"S": submission.model_dump_json()}},
                "ConditionExpression": "attribute_exists(pk)"}}]
            latest = entries.get(submission.racer)
            if latest is not None and latest.submission_id == submission.submission_id:
                entries[submission.racer] = submission.entry()
                items.append(self._board_put(submission.track, entries, version))
            if write_if(self._client, "transact_write_items", _SERVICE, TransactItems=items):
                return True
            if self.submission(submission.track, submission.racer, submission.submission_id) is None:
                return False  # deleted meanwhile (an admin removed the racer)
        raise Conflict("The league board is busy; the re-drive's result is stored on the next try.")

    def registered_tracks(self) -> dict[str, RegisteredTrack]:
        items = all_items(self._client, "query", _SERVICE, TableName=self._table,
                          KeyConditionExpression="pk = :pk", ExpressionAttributeValues={":pk": {"S": "LEAGUE#TRACKS"}})
        return {item["sk"]["S"].removeprefix("TRACK#"): RegisteredTrack.model_validate_json(item["body"]["S"])
                for item in items}

    def register_track(self, name: str, track: RegisteredTrack) -> None:
        self._call("put_item", TableName=self._table, Item={
            "pk": {"S": "LEAGUE#TRACKS"}, "sk": {"S": f"TRACK#{name}"}, "body": {"S": track.model_dump_json()}})

    def policy(self, track: str) -> LeaguePolicy:
        reply = self._call("get_item", TableName=self._table, Key={"pk": _pk(track), "sk": {"S": "POLICY"}})
        return LeaguePolicy.model_validate_json(reply["Item"]["body"]["S"]) if "Item" in reply else LeaguePolicy()

    def set_policy(self, track: str, policy: LeaguePolicy) -> None:
        self._call("put_item", TableName=self._table,
                   Item={"pk": _pk(track), "sk": {"S": "POLICY"}, "body": {"S": policy.model_dump_json()}})

    def evidence_owner(self, digest: str) -> str | None:
        reply = self._call("get_item", TableName=self._table, ConsistentRead=True, Key=_evidence_key(digest))
        return reply["Item"]["racer"]["S"] if "Item" in reply else None

    def submission(self, track: str, racer: str, submission_id: str) -> Submission | None:
        reply = self._call("get_item", TableName=self._table,
                           Key={"pk": _pk(track), "sk": _history_sk(racer, submission_id)})
        return Submission.model_validate_json(reply["Item"]["body"]["S"]) if "Item" in reply else None

    def remove_racer(self, track: str, racer: str) -> int:
        """Take the racer off the board and delete their history on this track; returns how many submissions."""
        keys = self._history_keys(track, racer)
        for _ in range(_ATTEMPTS):
            entries, version = self._board(track)
            if racer not in entries and not keys:
                return 0
            entries.pop(racer, None)
            if write_if(self._client, "transact_write_items", _SERVICE,
                        TransactItems=[self._board_put(track, entries, version)]):
                break
        else:
            raise Conflict("The league board is busy; delete again in a moment.")
        for key, digest in keys:
            if digest:  # the logs are free again: their real owner can push them (staff removed a copier)
                write_if(self._client, "delete_item", _SERVICE, TableName=self._table, Key=_evidence_key(digest),
                         ConditionExpression="racer = :racer", ExpressionAttributeValues={":racer": {"S": racer}})
            self._call("delete_item", TableName=self._table, Key=key)
        return max(len(keys), 1)

    def _history_keys(self, track: str, racer: str) -> list[tuple[dict[str, Any], str | None]]:
        items = all_items(self._client, "query", _SERVICE,
                          TableName=self._table, KeyConditionExpression="pk = :pk AND begins_with(sk, :prefix)",
                          ExpressionAttributeValues={":pk": _pk(track), ":prefix": {"S": f"RACER#{racer}#SUB#"}})
        return [({"pk": item["pk"], "sk": item["sk"]},
                 json.loads(item["body"]["S"]).get("evidence_digest") if "body" in item else None) for item in items]

    def _board(self, track: str) -> tuple[dict[str, BoardEntry], int | None]:
        reply = self._call("get_item", TableName=self._table, ConsistentRead=True,
                           Key={"pk": _pk(track), "sk": {"S": _BOARD_SK}})
        if "Item" not in reply:
            return {}, None
        item = reply["Item"]
        entries = {racer: BoardEntry.model_validate(entry) for racer, entry in json.loads(item["entries"]["S"]).items()}
        return entries, int(item["version"]["N"])

    def _board_put(self, track: str, entries: dict[str, BoardEntry], version: int | None) -> dict[str, Any]:
        item = {"pk": _pk(track), "sk": {"S": _BOARD_SK}, "version": {"N": str((version or 0) + 1)},
                "entries": {"S": json.dumps({racer: entry.model_dump(mode="json")
                                             for racer, entry in sorted(entries.items())})}}
        if version is None:
            return {"Put": {"TableName": self._table, "Item": item, "ConditionExpression": "attribute_not_exists(pk)"}}
        return {"Put": {"TableName": self._table, "Item": item, "ConditionExpression": "version = :seen",
                        "ExpressionAttributeValues": {":seen": {"N": str(version)}}}}

    def _call(self, operation: str, **kwargs: Any) -> Any:
        return call(self._client, operation, _SERVICE, **kwargs)

