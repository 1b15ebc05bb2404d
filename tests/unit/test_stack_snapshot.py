"""The unit tests' copied stack (tests/unit/stack_snapshot.py) is what a real bootstrap leaves, and nothing one test
writes reaches the next: the copy must not weaken the isolation `ensure_stack` after a wipe gave each test."""
from __future__ import annotations

from typing import Any

import pytest
from moto.core.base_backend import BackendDict

from drem_local.bootstrap import ensure_stack
from tests.unit.conftest import PASSWORD, STAGE
from tests.unit.stack_snapshot import fresh_stack

pytestmark = pytest.mark.unit


def _described(clients: Any, pool_id: str) -> dict[str, Any]:
    tables = sorted(clients.dynamodb.list_tables()["TableNames"])
    return {"tables": {name: clients.dynamodb.describe_table(TableName=name)["Table"]["KeySchema"] for name in tables},
            "buckets": sorted(bucket["Name"] for bucket in clients.s3.list_buckets()["Buckets"]),
            "groups": sorted(group["GroupName"] for group in clients.cognito.list_groups(UserPoolId=pool_id)["Groups"])}


def test_a_copied_stack_is_what_a_real_bootstrap_leaves(aws_clients: Any) -> None:
    real = ensure_stack(aws_clients, STAGE)
    expected = _described(aws_clients, real.user_pool_id)
    BackendDict.reset()
    fresh_stack(aws_clients, STAGE)  # the first may bootstrap for real: the second is a copy for sure
    BackendDict.reset()
    copied = fresh_stack(aws_clients, STAGE)
    assert copied.tables == real.tables and copied.buckets == real.buckets
    assert _described(aws_clients, copied.user_pool_id) == expected
    assert [pool["Id"] for pool in aws_clients.cognito.list_user_pools(MaxResults=10)["UserPools"]] == [
        copied.user_pool_id]


def test_what_one_test_writes_is_gone_from_the_next_tests_copy(aws_clients: Any) -> None:
    outputs = fresh_stack(aws_clients, STAGE)
    table, bucket = outputs.tables["races"], next(iter(outputs.buckets.values()))
    key_schema = aws_clients.dynamodb.describe_table(TableName=table)["Table"]["KeySchema"]
    aws_clients.dynamodb.put_item(TableName=table, Item={k["AttributeName"]: {"S": "x"} for k in key_schema})
    aws_clients.s3.put_object(Bucket=bucket, Key="left-behind", Body=b"x")
    aws_clients.cognito.admin_create_user(UserPoolId=outputs.user_pool_id, Username="left", TemporaryPassword=PASSWORD,
                                          MessageAction="SUPPRESS")
    BackendDict.reset()  # what fresh_moto does between tests

    again = fresh_stack(aws_clients, STAGE)
    assert aws_clients.dynamodb.scan(TableName=table)["Count"] == 0
    assert aws_clients.s3.list_objects_v2(Bucket=bucket)["KeyCount"] == 0
    assert aws_clients.cognito.list_users(UserPoolId=again.user_pool_id)["Users"] == []


def test_with_something_already_in_moto_the_stack_is_bootstrapped_around_it(aws_clients: Any) -> None:
    aws_clients.s3.create_bucket(Bucket="made-before-the-stack")
    outputs = fresh_stack(aws_clients, STAGE)
    names = {bucket["Name"] for bucket in aws_clients.s3.list_buckets()["Buckets"]}
    assert names == {"made-before-the-stack", *outputs.buckets.values()}
