"""DynamoDB adapter for sign-in state kept on the server (table `sessions`).

Items:
* `CHALLENGE#{id}` / `-`: a pending NEW_PASSWORD_REQUIRED step: the username and Cognito session Cognito answered,
  and `expires_at`. The browser holds only the random id (cookie `drem_challenge`), so it cannot name another
  account; the item is deleted when the step completes, so it cannot be replayed.
* `USER#{sub}` / `REVOKED`: `mark`, the user's RevocationMark as JSON: tokens of that user issued before it are
  refused. Written on sign-out, disable, enable, role change and deletion (chalicelib.auth.revocation).
"""
from __future__ import annotations

import secrets
import time
from typing import Any

from chalicelib.auth.revocation import RevocationMark
from chalicelib.domain.identity import NewPasswordChallenge
from chalicelib.storage.aws_errors import call

_SERVICE = "The session store"
CHALLENGE_TTL_S = 180


class DynamoSessionStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    # --- the new-password step ---------------------------------------------------------------------------------

    def hold_challenge(self, challenge: NewPasswordChallenge, ttl_s: int = CHALLENGE_TTL_S) -> str:
        challenge_id = secrets.token_urlsafe(32)
        call(self._client, "put_item", _SERVICE, TableName=self._table, Item={
            **_challenge_key(challenge_id), "username": {"S": challenge.username},
            "session": {"S": challenge.session}, "expires_at": {"N": str(int(time.time()) + ttl_s)}})
        return challenge_id

    def challenge(self, challenge_id: str) -> NewPasswordChallenge | None:
        if not challenge_id or len(challenge_id) > 128:
            return None
        item = call(self._client, "get_item", _SERVICE, TableName=self._table, Key=_challenge_key(challenge_id),
                    ConsistentRead=True).get("Item")
        if not item or int(item["expires_at"]["N"]) <= time.time():
            return None
        return NewPasswordChallenge(username=item["username"]["S"], session=item["session"]["S"])

    def forget_challenge(self, challenge_id: str) -> None:
        if challenge_id and len(challenge_id) <= 128:
            call(self._client, "delete_item", _SERVICE, TableName=self._table, Key=_challenge_key(challenge_id))

    # --- revocation --------------------------------------------------------------------------------------------

    def mark(self, sub: str) -> RevocationMark | None:
        item = call(self._client, "get_item", _SERVICE, TableName=self._table, Key=_revocation_key(sub),
                    ConsistentRead=True).get("Item")
        return RevocationMark.model_validate_json(item["mark"]["S"]) if item and "mark" in item else None

    def put_mark(self, sub: str, mark: RevocationMark) -> None:
        call(self._client, "put_item", _SERVICE, TableName=self._table,
             Item={**_revocation_key(sub), "mark": {"S": mark.model_dump_json()}})


def _challenge_key(challenge_id: str) -> dict[str, dict[str, str]]:
    return {"pk": {"S": f"CHALLENGE#{challenge_id}"}, "sk": {"S": "-"}}


def _revocation_key(sub: str) -> dict[str, dict[str, str]]:
    return {"pk": {"S": f"USER#{sub}"}, "sk": {"S": "REVOKED"}}

