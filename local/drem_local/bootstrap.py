"""Create drem's tables, buckets and user pool from `drem_infra.resources`, idempotently, with boto3.

Used against the local durable moto server (and in-process `mock_aws` in tests). Not via moto CloudFormation: it
reports CREATE_COMPLETE while silently skipping every Cognito resource. Existing resources are found by name, so a
second run changes nothing and returns the same ids.
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from typing import Any

from botocore.config import Config
from botocore.exceptions import ClientError

from drem_infra import resources
from drem_infra.resources import BucketSpec, TableSpec
from drem_local.storage_keys import StorageKeys, sign_every_call


class StackDriftError(RuntimeError):
    """An existing resource has a shape that differs from `drem_infra.resources` (it will not be altered)."""


@dataclass(frozen=True)
class AwsClients:
    dynamodb: Any
    s3: Any
    cognito: Any
    region: str


@dataclass(frozen=True)
class StackOutputs:
    stage: str
    region: str
    user_pool_id: str
    user_pool_client_id: str
    tables: dict[str, str] = field(default_factory=dict)
    buckets: dict[str, str] = field(default_factory=dict)

    def to_env(self) -> dict[str, str]:
        """The environment contract the app reads (same variable names CDK sets on AWS)."""
        return resources.stage_environment(self.stage, self.user_pool_id, self.user_pool_client_id,
                                           self.tables, self.buckets)

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> StackOutputs:
        data = json.loads(text)
        return cls(
            stage=data["stage"],
            region=data["region"],
            user_pool_id=data["user_pool_id"],
            user_pool_client_id=data["user_pool_client_id"],
            tables=dict(data.get("tables", {})),
            buckets=dict(data.get("buckets", {})),
        )


@dataclass(frozen=True)
class AdminCredentials:
    username: str
    # None when the user already existed and no password was given: an existing password is never reset.
    password: str | None
    created: bool


def _boto_session(region: str, **credentials: str) -> Any:
    from drem_local.app_source import use_app_source

    use_app_source()
    from chalicelib.storage.clients import boto_session  # one reader of botocore's JSON for every client made

    return boto_session(region, **credentials)


def clients_for(endpoint_url: str | None, region: str, keys: StorageKeys | None = None) -> AwsClients:
    """boto3 clients for the local storage server (signed with the installation's `keys`, which it requires) or,
    with no endpoint, the default chain / mock_aws."""
    credentials: dict[str, str] = {}
    if endpoint_url:
        if keys is None:
            raise ValueError("the local storage server accepts only the installation's keys: pass them "
                             "(drem_local.storage_keys.load_or_create(state_dir))")
        credentials = keys.boto_kwargs()
    session = _boto_session(region, **credentials)
    # botocore 1.44 otherwise routes some DynamoDB calls to account-specific hosts moto does not serve.
    base = Config(account_id_endpoint_mode="disabled", retries={"max_attempts": 3, "mode": "standard"})
    # s3v4: moto checks SigV2 presigned PUTs on the browser's CORS preflight and rejects them.
    s3_config = base.merge(Config(signature_version="s3v4"))
    if endpoint_url:
        s3_config = s3_config.merge(Config(s3={"addressing_style": "path"}))
    return AwsClients(
        dynamodb=session.client("dynamodb", endpoint_url=endpoint_url, config=base),
        s3=session.client("s3", endpoint_url=endpoint_url, config=s3_config),
        cognito=sign_every_call(session.client("cognito-idp", endpoint_url=endpoint_url, config=base))
        if endpoint_url else session.client("cognito-idp", config=base),
        region=region,
    )


def ensure_stack(clients: AwsClients, stage: str = "local") -> StackOutputs:
    env = os.environ
    tables = {spec.logical: resources.table_name(stage, spec.logical, env) for spec in resources.TABLES}
    buckets = {spec.logical: resources.bucket_name(stage, spec.logical, env) for spec in resources.BUCKETS}

    existing_tables = _list_tables(clients.dynamodb)
    for spec in resources.TABLES:
        _ensure_table(clients.dynamodb, spec, tables[spec.logical], existing_tables)

    existing_buckets = {b["Name"] for b in clients.s3.list_buckets().get("Buckets", [])}
    for bucket in resources.BUCKETS:
        _ensure_bucket(clients.s3, bucket, buckets[bucket.logical], existing_buckets, clients.region)

    pool_id = _ensure_user_pool(clients.cognito, resources.user_pool_name(stage))
    client_id = _ensure_user_pool_client(clients.cognito, pool_id, resources.client_name(stage))
    _ensure_groups(clients.cognito, pool_id)
    return StackOutputs(stage=stage, region=clients.region, user_pool_id=pool_id,
                        user_pool_client_id=client_id, tables=tables, buckets=buckets)


def ensure_admin(clients: AwsClients, outputs: StackOutputs, username: str = "admin",
                 password: str | None = None, email: str | None = None) -> AdminCredentials:
    """Make sure `username` exists in group admin with a permanent password; never resets an existing password
    unless one is passed explicitly. `email` (the pool requires one) defaults to a local placeholder."""
    cognito, pool_id = clients.cognito, outputs.user_pool_id
    try:
        cognito.admin_get_user(UserPoolId=pool_id, Username=username)
        exists = True
    except cognito.exceptions.UserNotFoundException:
        exists = False

    if not exists:
        password = password or generate_password()
        cognito.admin_create_user(
            UserPoolId=pool_id, Username=username, TemporaryPassword=password, MessageAction="SUPPRESS",
            UserAttributes=[{"Name": "email", "Value": email or f"{username}@drem.local"},
                            {"Name": "email_verified", "Value": "true"}],
        )
    if password is not None:
        # Permanent, so the first login is not a NEW_PASSWORD_REQUIRED challenge.
        cognito.admin_set_user_password(UserPoolId=pool_id, Username=username, Password=password, Permanent=True)
    cognito.admin_add_user_to_group(UserPoolId=pool_id, Username=username, GroupName="admin")
    return AdminCredentials(username=username, password=password, created=not exists)


def generate_password(length: int = 20) -> str:
    """A random password that meets `resources.USER_POOL.password_policy`."""
    return resources.USER_POOL.password_policy.random_password(length)


# --- DynamoDB -------------------------------------------------------------------------------------------------

def _list_tables(dynamodb) -> set[str]:
    names: set[str] = set()
    for page in dynamodb.get_paginator("list_tables").paginate():
        names.update(page.get("TableNames", []))
    return names


def _key_schema(pk: str, sk: str) -> list[dict[str, str]]:
    return [{"AttributeName": pk, "KeyType": "HASH"}, {"AttributeName": sk, "KeyType": "RANGE"}]


def _ensure_table(dynamodb, spec: TableSpec, name: str, existing: set[str]) -> None:
    if name in existing:
        _check_table_shape(dynamodb, spec, name)
        return
    params: dict[str, Any] = {
        "TableName": name,
        "BillingMode": "PAY_PER_REQUEST",
        "AttributeDefinitions": [{"AttributeName": a, "AttributeType": "S"} for a in spec.key_attributes],
        "KeySchema": _key_schema(spec.pk, spec.sk),
    }
    if spec.gsis:
        params["GlobalSecondaryIndexes"] = [
            {"IndexName": g.name, "KeySchema": _key_schema(g.pk, g.sk), "Projection": {"ProjectionType": "ALL"}}
            for g in spec.gsis
        ]
    if spec.stream:
        params["StreamSpecification"] = {"StreamEnabled": True, "StreamViewType": "NEW_AND_OLD_IMAGES"}
    status = dynamodb.create_table(**params)["TableDescription"].get("TableStatus")
    if status != "ACTIVE":
        dynamodb.get_waiter("table_exists").wait(TableName=name)


def _check_table_shape(dynamodb, spec: TableSpec, name: str) -> None:
    table = dynamodb.describe_table(TableName=name)["Table"]
    found = {
        "key": table["KeySchema"],
        "gsis": {g["IndexName"]: g["KeySchema"] for g in table.get("GlobalSecondaryIndexes", [])},
    }
    wanted = {"key": _key_schema(spec.pk, spec.sk), "gsis": {g.name: _key_schema(g.pk, g.sk) for g in spec.gsis}}
    if found != wanted:
        raise StackDriftError(f"table {name} exists with keys {found}, but drem_infra.resources defines {wanted}; "
                              "delete it (or the local state) to recreate it")


# --- S3 -------------------------------------------------------------------------------------------------------

def _cors_rules() -> list[dict[str, Any]]:
    cors = resources.BROWSER_UPLOAD_CORS
    return [{
        "AllowedHeaders": list(cors.allowed_headers),
        "AllowedMethods": list(cors.allowed_methods),
        "AllowedOrigins": list(cors.allowed_origins),
        "ExposeHeaders": list(cors.expose_headers),
        "MaxAgeSeconds": cors.max_age_seconds,
    }]


def _ensure_bucket(s3, spec: BucketSpec, name: str, existing: set[str], region: str) -> None:
    if name not in existing:
        params: dict[str, Any] = {"Bucket": name}
        if region != "us-east-1":
            params["CreateBucketConfiguration"] = {"LocationConstraint": region}
        s3.create_bucket(**params)
    if spec.cors and _current_cors(s3, name) != _cors_rules():
        s3.put_bucket_cors(Bucket=name, CORSConfiguration={"CORSRules": _cors_rules()})


def _current_cors(s3, name: str) -> list[dict[str, Any]] | None:
    try:
        rules = s3.get_bucket_cors(Bucket=name)["CORSRules"]
    except ClientError as exc:
        if exc.response["Error"]["Code"] == "NoSuchCORSConfiguration":
            return None
        raise
    return [{k: v for k, v in rule.items() if k != "ID"} for rule in rules]


# --- Cognito --------------------------------------------------------------------------------------------------

def _ensure_user_pool(cognito, name: str) -> str:
    for page in cognito.get_paginator("list_user_pools").paginate(MaxResults=60):
        for pool in page.get("UserPools", []):
            if pool["Name"] == name:
                return pool["Id"]
    spec = resources.USER_POOL
    policy = spec.password_policy
    created = cognito.create_user_pool(
        PoolName=name,
        Policies={"PasswordPolicy": {
            "MinimumLength": policy.minimum_length,
            "RequireLowercase": policy.require_lowercase,
            "RequireUppercase": policy.require_uppercase,
            "RequireNumbers": policy.require_digits,
            "RequireSymbols": policy.require_symbols,
            "TemporaryPasswordValidityDays": policy.temporary_password_validity_days,
        }},
        AutoVerifiedAttributes=list(spec.auto_verified_attributes),
        UsernameConfiguration={"CaseSensitive": False},
        AdminCreateUserConfig={"AllowAdminCreateUserOnly": not spec.self_sign_up},
        Schema=[
            *({"Name": name, "AttributeDataType": "String", "Required": True, "Mutable": True}
              for name in spec.required_attributes),
            *({"Name": a.name, "AttributeDataType": a.data_type, "Mutable": a.mutable}
              for a in spec.custom_attributes),
        ],
    )
    return created["UserPool"]["Id"]


def _ensure_user_pool_client(cognito, pool_id: str, name: str) -> str:
    for page in cognito.get_paginator("list_user_pool_clients").paginate(UserPoolId=pool_id, MaxResults=60):
        for client in page.get("UserPoolClients", []):
            if client["ClientName"] == name:
                return client["ClientId"]
    spec = resources.USER_POOL
    created = cognito.create_user_pool_client(
        UserPoolId=pool_id,
        ClientName=name,
        GenerateSecret=spec.generate_secret,
        ExplicitAuthFlows=list(spec.explicit_auth_flows),
        ReadAttributes=list(spec.read_attributes),
        WriteAttributes=list(spec.write_attributes),
    )
    return created["UserPoolClient"]["ClientId"]


def _ensure_groups(cognito, pool_id: str) -> None:
    existing: set[str] = set()
    for page in cognito.get_paginator("list_groups").paginate(UserPoolId=pool_id):
        existing.update(g["GroupName"] for g in page.get("Groups", []))
    for group in resources.GROUPS:
        if group not in existing:
            cognito.create_group(UserPoolId=pool_id, GroupName=group)
