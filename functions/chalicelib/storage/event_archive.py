"""The storage side of `drem export` / `drem import`: raw items, objects and accounts of one stack.

Works against whatever endpoint it is given: the local durable moto server (endpoint + names from the state dir's
stack.json) or real AWS (default credential chain, names from the environment contract). Items travel as DynamoDB
attribute-value JSON; binary values as base64 text. Implements `StackReader` / `StackWriter` of
`chalicelib.domain.event_transfer.ports`.
"""
from __future__ import annotations

import base64
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from botocore.exceptions import BotoCoreError, ClientError

from chalicelib.core.errors import InvalidInput
from chalicelib.formats.event_export.records import Account, Item
from chalicelib.formats.logo_image import LogoImage
from chalicelib.storage.aws_errors import all_items, error_code, translate_common, write_if
from chalicelib.storage.event_logos import DynamoLogoStore
from chalicelib.storage.users import COUNTRY_ATTRIBUTE, translate_account_error

# Where `drem up` keeps the keys its storage server accepts (drem_local.storage_keys.KEYS_FILE).
_LOCAL_KEYS_FILE = "storage-keys.json"


@dataclass(frozen=True)
class StackLocation:
    """Where a stack's data lives: endpoint (None on AWS), region, physical names."""
    region: str
    user_pool_id: str
    tables: dict[str, str] = field(default_factory=dict)
    buckets: dict[str, str] = field(default_factory=dict)
    endpoint_url: str | None = None
    # The local storage server's keys (access key id, secret); None on AWS (default credential chain).
    local_keys: tuple[str, str] | None = field(default=None, repr=False)

    @classmethod
    def from_state_dir(cls, state_dir: Path) -> StackLocation:
        try:
            info = json.loads((state_dir / "stack.json").read_text())
            outputs = info["outputs"]
            keys = json.loads((state_dir / _LOCAL_KEYS_FILE).read_text())
            return cls(region=outputs["region"], user_pool_id=outputs["user_pool_id"], tables=dict(outputs["tables"]),
                       buckets=dict(outputs["buckets"]), endpoint_url=info["urls"]["storage"],
                       local_keys=(keys["access_key_id"], keys["secret_access_key"]))
        except (OSError, ValueError, KeyError, TypeError):
            raise InvalidInput(f"{state_dir / 'stack.json'} or {_LOCAL_KEYS_FILE} is missing or unreadable (or not "
                               f"yours): start the local stack with "
                               f"`drem up --state-dir {state_dir}` first (or use --aws).", field="state_dir") from None

    @classmethod
    def from_environment(cls, env: Mapping[str, str], stage: str | None = None,
                         user_pool_id: str | None = None) -> StackLocation:
        from drem_infra import resources

        stage = stage or env.get("DREM_STAGE") or "local"
        pool = user_pool_id or env.get("DREM_USER_POOL_ID")
        if not pool:
            raise InvalidInput("Give the user pool id with --user-pool-id or $DREM_USER_POOL_ID.",
                               field="user_pool_id")
        return cls(region=env.get("AWS_REGION") or env.get("AWS_DEFAULT_REGION") or "us-east-1", user_pool_id=pool,
                   tables={s.logical: resources.table_name(stage, s.logical, env) for s in resources.TABLES},
                   buckets={s.logical: resources.bucket_name(stage, s.logical, env) for s in resources.BUCKETS},
                   endpoint_url=env.get("AWS_ENDPOINT_URL") or None)


def connect(location: StackLocation) -> StackStorage:
    import boto3
    from botocore.config import Config

    from chalicelib.storage.clients import sign_every_call

    credentials: dict[str, str] = {}
    if location.endpoint_url:  # the local storage server: its own keys, never a shell profile's
        if location.local_keys is None:
            raise InvalidInput("the local storage server needs the installation's keys: give --state-dir",
                               field="state_dir")
        credentials = {"aws_access_key_id": location.local_keys[0], "aws_secret_access_key": location.local_keys[1]}
    session = boto3.session.Session(region_name=location.region, **credentials)
    base = Config(account_id_endpoint_mode="disabled", retries={"max_attempts": 3, "mode": "standard"})
    s3_config = base.merge(Config(signature_version="s3v4",
                                  s3={"addressing_style": "path"} if location.endpoint_url else {}))
    cognito = session.client("cognito-idp", endpoint_url=location.endpoint_url, config=base)
    return StackStorage(location,
                        dynamodb=session.client("dynamodb", endpoint_url=location.endpoint_url, config=base),
                        s3=session.client("s3", endpoint_url=location.endpoint_url, config=s3_config),
                        cognito=sign_every_call(cognito) if location.endpoint_url else cognito)


class StackStorage:
    def __init__(self, location: StackLocation, *, dynamodb: Any, s3: Any, cognito: Any) -> None:
        self._location = location
        self._dynamodb = dynamodb
        self._s3 = s3
        self._cognito = cognito
        self._accounts: dict[str, Account] | None = None

    # --- items ------------------------------------------------------------------------------------------------------

    def get_item(self, table: str, pk: str, sk: str) -> Item | None:
        reply = self._db("get_item", table, Key={"pk": {"S": pk}, "sk": {"S": sk}}, ConsistentRead=True)
        return _to_json(reply["Item"]) if "Item" in reply else None

    def partition(self, table: str, pk: str, sk_prefix: str = "") -> list[Item]:
        condition, values = "pk = :pk", {":pk": {"S": pk}}
        if sk_prefix:
            condition += " AND begins_with(sk, :prefix)"
            values[":prefix"] = {"S": sk_prefix}
        items = all_items(self._dynamodb, "query", f"The {table} table", TableName=self._table(table),
                          KeyConditionExpression=condition, ExpressionAttributeValues=values, ConsistentRead=True)
        return [_to_json(i) for i in items]

    def put_new_item(self, table: str, item: Item) -> bool:
        return write_if(self._dynamodb, "put_item", f"The {table} table", TableName=self._table(table),
                        Item=_from_json(item), ConditionExpression="attribute_not_exists(pk)")

    # --- objects ----------------------------------------------------------------------------------------------------

    def read_object(self, bucket: str, key: str) -> bytes | None:
        try:
            return self._s3.get_object(Bucket=self._bucket(bucket), Key=key)["Body"].read()
        except ClientError as exc:
            if error_code(exc) in {"NoSuchKey", "404"}:
                return None
            raise translate_common(exc, f"The {bucket} bucket") from exc
        except BotoCoreError as exc:
            raise translate_common(exc, f"The {bucket} bucket") from exc

    def write_object(self, bucket: str, key: str, data: bytes) -> None:
        try:
            self._s3.put_object(Bucket=self._bucket(bucket), Key=key, Body=data)
        except (ClientError, BotoCoreError) as exc:
            raise translate_common(exc, f"The {bucket} bucket") from exc

    # --- the event's logo (its item's shape is the logo store's) ---------------------------------------------------

    def read_logo(self, event_id: str) -> LogoImage | None:
        return self._logos().get(event_id)

    def write_logo(self, event_id: str, logo: LogoImage) -> None:
        self._logos().put(event_id, logo)

    def _logos(self) -> DynamoLogoStore:
        return DynamoLogoStore(self._dynamodb, self._table("events"))

    # --- boards -----------------------------------------------------------------------------------------------------

    def recompute_boards(self, event_item: Item) -> None:
        """Rebuild the event's boards from its races on this stack, as the race admin's "recompute" does, with the
        event taken from `event_item` (the import writes the event item only after this). A board already equal to
        the recomputed one is left untouched, so an honest export round-trips byte for byte."""
        import time

        from chalicelib.domain.events import Event
        from chalicelib.domain.leaderboards import LeaderboardPublisher
        from chalicelib.domain.profiles import ProfileService, ProfilesForBoards
        from chalicelib.domain.races import RaceService
        from chalicelib.storage.leaderboards import DynamoBoardStore
        from chalicelib.storage.profiles import DynamoProfileStore
        from chalicelib.storage.races import DynamoRaceStore

        event = Event.model_validate_json(event_item["doc"]["S"])
        tables = self._location.tables
        profiles = ProfilesForBoards(ProfileService(DynamoProfileStore(self._dynamodb, tables["profiles"])))
        def clock_ms() -> int:
            return time.time_ns() // 1_000_000

        publisher = LeaderboardPublisher(DynamoBoardStore(self._dynamodb, tables["leaderboards"]), clock_ms,
                                         cache=None)
        service = RaceService(DynamoRaceStore(self._dynamodb, tables["races"]), _OneEvent(event), _NoRacers(),
                              profiles, publisher, clock_ms)
        service.recompute(event.event_id)

    # --- accounts ---------------------------------------------------------------------------------------------------

    def accounts_by_sub(self) -> dict[str, Account]:
        if self._accounts is None:
            pages = self._cognito_call("", "list_users", paginate=True, UserPoolId=self._location.user_pool_id)
            found = {}
            for page in pages:
                for raw in page.get("Users", []):
                    account = self._account(raw)
                    found[account.sub] = account
            self._accounts = found
        return self._accounts

    def find_account(self, username: str) -> Account | None:
        try:
            reply = self._cognito.admin_get_user(UserPoolId=self._location.user_pool_id, Username=username)
        except ClientError as exc:
            if error_code(exc) == "UserNotFoundException":
                return None
            raise translate_account_error(exc, username) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, "The account service") from exc
        return self._account({**reply, "Attributes": reply.get("UserAttributes", [])})

    def create_account(self, account: Account, temporary_password: str) -> str:
        """The same username, a temporary password (FORCE_CHANGE_PASSWORD), the same roles; returns the new sub."""
        pool, name = self._location.user_pool_id, account.username
        attributes = [{"Name": "email_verified", "Value": "true"}] if account.email else []
        attributes += [{"Name": n, "Value": v} for n, v in (("email", account.email),
                                                            (COUNTRY_ATTRIBUTE, account.country_code)) if v]
        reply = self._cognito_call(name, "admin_create_user", UserPoolId=pool, Username=name,
                                   TemporaryPassword=temporary_password, MessageAction="SUPPRESS",
                                   UserAttributes=attributes)
        for group in account.groups:
            self._cognito_call(name, "admin_add_user_to_group", UserPoolId=pool, Username=name, GroupName=group)
        if not account.enabled:
            self._cognito_call(name, "admin_disable_user", UserPoolId=pool, Username=name)
        return _attributes(reply["User"]).get("sub", "")

    def finish_account(self, account: Account) -> None:
        """What `create_account` does after creating it, for an account an interrupted import created: the groups it
        lacks are added and it is disabled if the export says so (both idempotent)."""
        pool, name = self._location.user_pool_id, account.username
        pages = self._cognito_call(name, "admin_list_groups_for_user", paginate=True, UserPoolId=pool, Username=name)
        present = {g["GroupName"] for page in pages for g in page.get("Groups", [])}
        for group in account.groups:
            if group not in present:
                self._cognito_call(name, "admin_add_user_to_group", UserPoolId=pool, Username=name, GroupName=group)
        if not account.enabled:
            self._cognito_call(name, "admin_disable_user", UserPoolId=pool, Username=name)

    def _account(self, raw: dict[str, Any]) -> Account:
        attributes = _attributes(raw)
        username = raw["Username"]
        pages = self._cognito_call(username, "admin_list_groups_for_user", paginate=True,
                                   UserPoolId=self._location.user_pool_id, Username=username)
        groups = sorted(g["GroupName"] for page in pages for g in page.get("Groups", []))
        return Account(username=username, sub=attributes.get("sub", ""), email=attributes.get("email"),
                       country_code=attributes.get(COUNTRY_ATTRIBUTE), groups=groups,
                       enabled=raw.get("Enabled", True))

    # --- plumbing ---------------------------------------------------------------------------------------------------

    def _table(self, logical: str) -> str:
        return self._location.tables[logical]

    def _bucket(self, logical: str) -> str:
        return self._location.buckets[logical]

    def _db(self, operation: str, table: str, **kwargs: Any) -> dict[str, Any]:
        try:
            return getattr(self._dynamodb, operation)(TableName=self._table(table), **kwargs)
        except (ClientError, BotoCoreError) as exc:
            raise translate_common(exc, f"The {table} table") from exc

    def _cognito_call(self, username: str, operation: str, *, paginate: bool = False, **kwargs: Any) -> Any:
        try:
            if paginate:
                return list(self._cognito.get_paginator(operation).paginate(**kwargs))
            return getattr(self._cognito, operation)(**kwargs)
        except (ClientError, BotoCoreError) as exc:
            raise translate_account_error(exc, username) from exc


class _OneEvent:
    """The event being imported, served before its item is written."""

    def __init__(self, event: Any) -> None:
        self._event = event

    def get(self, event_id: str) -> Any:
        return self._event if event_id == self._event.event_id else None


class _NoRacers:
    """Recomputing boards never looks racers up (that is for creating races)."""

    def __getattr__(self, name: str) -> Any:
        raise AttributeError(f"recompute does not use the racer directory ({name})")


def _attributes(raw: dict[str, Any]) -> dict[str, str]:
    return {a["Name"]: a.get("Value", "") for a in raw.get("Attributes", [])}


def _to_json(item: dict[str, Any]) -> Item:
    """An item as JSON: binary values (B/BS) as base64 text, everything else as DynamoDB returns it."""
    return {name: _convert(value, lambda raw: base64.b64encode(raw).decode()) for name, value in item.items()}


def _from_json(item: Item) -> dict[str, Any]:
    return {name: _convert(value, base64.b64decode) for name, value in item.items()}


def _convert(value: dict[str, Any], binary: Any) -> dict[str, Any]:
    (kind, inner), = value.items()
    if kind == "B":
        inner = binary(inner)
    elif kind == "BS":
        inner = [binary(b) for b in inner]
    elif kind == "M":
        inner = {k: _convert(v, binary) for k, v in inner.items()}
    elif kind == "L":
        inner = [_convert(v, binary) for v in inner]
    return {kind: inner}
