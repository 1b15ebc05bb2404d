"""DynamoDB adapter for model evaluations (table `models`, beside the model records).

Items: `EVALS#{ownerSub}` / `{modelId}#{recordedAt}`, body = the Evaluation as JSON. One Query per owner gives every
evaluation of every version of that owner's models (what the registry plots), without touching the model items
(`OWNER#…`) or the operator listing index (no gsi1 attributes).
"""
from __future__ import annotations

from typing import Any

from chalicelib.domain.model_registry import Evaluation
from chalicelib.storage.aws_errors import call

_SERVICE = "The evaluation store"


class DynamoEvaluationStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    def add(self, owner_sub: str, evaluation: Evaluation) -> None:
        self._call("put_item", TableName=self._table, Item={
            "pk": {"S": f"EVALS#{owner_sub}"}, "sk": {"S": f"{evaluation.model_id}#{evaluation.recorded_at}"},
            "body": {"S": evaluation.model_dump_json()}})

    def for_owner(self, owner_sub: str) -> list[Evaluation]:
        found: list[Evaluation] = []
        request: dict[str, Any] = dict(TableName=self._table, KeyConditionExpression="pk = :pk",
                                       ExpressionAttributeValues={":pk": {"S": f"EVALS#{owner_sub}"}})
        while True:
            reply = self._call("query", **request)
            found.extend(Evaluation.model_validate_json(item["body"]["S"]) for item in reply.get("Items", []))
            if "LastEvaluatedKey" not in reply or len(found) >= 5000:
                return found
            request["ExclusiveStartKey"] = reply["LastEvaluatedKey"]

    def _call(self, operation: str, **kwargs: Any) -> Any:
        return call(self._client, operation, _SERVICE, **kwargs)

