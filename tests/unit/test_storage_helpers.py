"""The two helpers every DynamoDB adapter writes and pages through: `write_if` (a conditional write that reports
whether it applied) and `all_items` (a query or scan followed to its last page), against moto's DynamoDB."""
from __future__ import annotations

from itertools import islice
from typing import Any

import pytest
from botocore.stub import Stubber

from chalicelib.core.errors import RateLimited
from chalicelib.storage.aws_errors import all_items, write_if

pytestmark = pytest.mark.unit

_TABLE = "helpers-test"
_SERVICE = "The test table"


@pytest.fixture
def dynamodb(aws_clients: Any) -> Any:
    client = aws_clients.dynamodb
    client.create_table(TableName=_TABLE, BillingMode="PAY_PER_REQUEST",
                        AttributeDefinitions=[{"AttributeName": "pk", "AttributeType": "S"},
                                              {"AttributeName": "sk", "AttributeType": "S"}],
                        KeySchema=[{"AttributeName": "pk", "KeyType": "HASH"},
                                   {"AttributeName": "sk", "KeyType": "RANGE"}])
    return client


def _item(sk: str, value: str = "") -> dict[str, Any]:
    return {"pk": {"S": "P"}, "sk": {"S": sk}, "value": {"S": value}}


def _stored(dynamodb: Any, sk: str) -> dict[str, Any] | None:
    return dynamodb.get_item(TableName=_TABLE, Key={"pk": {"S": "P"}, "sk": {"S": sk}}, ConsistentRead=True).get("Item")


def test_a_conditional_write_says_whether_it_applied_and_a_refused_one_changes_nothing(dynamodb):
    new = {"TableName": _TABLE, "ConditionExpression": "attribute_not_exists(pk)"}
    assert write_if(dynamodb, "put_item", _SERVICE, Item=_item("a", "first"), **new) is True
    assert write_if(dynamodb, "put_item", _SERVICE, Item=_item("a", "second"), **new) is False
    assert _stored(dynamodb, "a")["value"] == {"S": "first"}


def test_a_transaction_whose_condition_fails_writes_none_of_its_items(dynamodb):
    dynamodb.put_item(TableName=_TABLE, Item=_item("taken"))
    applied = write_if(dynamodb, "transact_write_items", _SERVICE, TransactItems=[
        {"Put": {"TableName": _TABLE, "Item": _item("fresh"), "ConditionExpression": "attribute_not_exists(pk)"}},
        {"Put": {"TableName": _TABLE, "Item": _item("taken"), "ConditionExpression": "attribute_not_exists(pk)"}}])
    assert applied is False
    assert _stored(dynamodb, "fresh") is None


def test_any_other_refusal_is_still_an_error_not_a_failed_condition(dynamodb):
    with Stubber(dynamodb) as stub:
        stub.add_client_error("put_item", service_error_code="ProvisionedThroughputExceededException")
        with pytest.raises(RateLimited):
            write_if(dynamodb, "put_item", _SERVICE, TableName=_TABLE, Item=_item("a"))


def test_all_items_follows_every_page_and_reads_no_page_it_does_not_need(dynamodb):
    for n in range(5):
        dynamodb.put_item(TableName=_TABLE, Item=_item(f"s{n}"))
    queries: list[Any] = []
    dynamodb.meta.events.register("before-call.dynamodb.Query", lambda **kwargs: queries.append(kwargs))
    query = {"TableName": _TABLE, "KeyConditionExpression": "pk = :pk",
             "ExpressionAttributeValues": {":pk": {"S": "P"}}, "Limit": 2}

    everything = [item["sk"]["S"] for item in all_items(dynamodb, "query", _SERVICE, **query)]
    assert everything == ["s0", "s1", "s2", "s3", "s4"] and len(queries) == 3

    queries.clear()
    first_three = list(islice(all_items(dynamodb, "query", _SERVICE, **query), 3))
    assert [item["sk"]["S"] for item in first_three] == ["s0", "s1", "s2"] and len(queries) == 2
