"""DynamoDB adapter for racer profiles (`profiles` table): `USER#{sub}`/`PROFILE` plus a username alias item
`USERNAME#{lower(username)}`/`SUB` so public look-ups by name are one GetItem each, with no Cognito call."""
from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from chalicelib.domain.profiles import Profile
from chalicelib.storage.aws_errors import batch_items, call

_SERVICE = "The profile store"
_FIELDS = ("username", "display_name", "country_code", "highlight_colour", "avatar", "updated_at")


def _profile(sub: str, item: dict[str, Any]) -> Profile:
    values = {name: item[name]["S"] for name in _FIELDS if name in item}
    return Profile(sub=sub, deleted=item.get("deleted", {}).get("BOOL", False), **values)


def _profile_key(sub: str) -> dict[str, Any]:
    return {"pk": {"S": f"USER#{sub}"}, "sk": {"S": "PROFILE"}}


def _alias_key(username: str) -> dict[str, Any]:
    # Cognito usernames are case-insensitive in drem's pool, so the alias is too.
    return {"pk": {"S": f"USERNAME#{username.casefold()}"}, "sk": {"S": "SUB"}}


class DynamoProfileStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    def get(self, sub: str) -> Profile | None:
        item = self._get(_profile_key(sub))
        return None if item is None else _profile(sub, item)

    def get_many(self, subs: Iterable[str]) -> dict[str, Profile]:
        """Many profiles in BatchGetItem calls of 100 keys (printed results name hundreds of racers at once)."""
        keys = [_profile_key(sub) for sub in dict.fromkeys(subs)]
        found: dict[str, Profile] = {}
        for item in batch_items(self._client, self._table, keys, _SERVICE, ConsistentRead=True):
            sub = item["pk"]["S"].removeprefix("USER#")
            found[sub] = _profile(sub, item)
        return found

    def put(self, profile: Profile) -> None:
        item = {**_profile_key(profile.sub), "sub": {"S": profile.sub}, "deleted": {"BOOL": profile.deleted}}
        for name in _FIELDS:
            value = getattr(profile, name)
            if value is not None and not profile.deleted:
                item[name] = {"S": value}
        if profile.deleted and profile.updated_at:
            item["updated_at"] = {"S": profile.updated_at}
        self._call("put_item", TableName=self._table, Item=item)

    def sub_for_username(self, username: str) -> str | None:
        item = self._get(_alias_key(username))
        return item["sub"]["S"] if item else None

    def subs_for_usernames(self, usernames: Iterable[str]) -> dict[str, str]:
        """{case-folded sign-in name: sub} of many names in BatchGetItem calls of 100 keys (a board's racers at once);
        names without an alias are left out."""
        keys = [_alias_key(name) for name in dict.fromkeys(name.casefold() for name in usernames)]
        return {item["pk"]["S"].removeprefix("USERNAME#"): item["sub"]["S"]
                for item in batch_items(self._client, self._table, keys, _SERVICE, ConsistentRead=True)}

    def link_username(self, username: str, sub: str) -> None:
        self._call("put_item", TableName=self._table, Item={**_alias_key(username), "sub": {"S": sub}})

    def unlink_username(self, username: str) -> None:
        self._call("delete_item", TableName=self._table, Key=_alias_key(username))

    def _get(self, key: dict[str, Any]) -> dict[str, Any] | None:
        return self._call("get_item", TableName=self._table, Key=key, ConsistentRead=True).get("Item")

    def _call(self, operation: str, **kwargs: Any) -> dict[str, Any]:
        return call(self._client, operation, _SERVICE, **kwargs)
