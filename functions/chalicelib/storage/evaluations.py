"""DynamoDB adapter for model evaluations (table `models`, beside the model records).

Items: `EVALS#{ownerSub}` / `{modelId}#{recordedAt}`, body = the Evaluation as JSON. One Query per owner gives every
evaluation of every version of that owner's models (what the registry plots), without touching the model items
(`OWNER#…`) or the operator listing index (no gsi1 attributes).
"""
from __future__ import annotations

from itertools import islice
from typing import Any

from chalicelib.domain.model_registry import Evaluation
from chalicelib.storage.aws_errors import all_items, call

_SERVICE = "The evaluation store"
# A bound on what one owner's chart reads, whatever a runaway client recorded.
_MOST_EVALUATIONS = 5000


class DynamoEvaluationStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    def add(self, owner_sub: str, evaluation: Evaluation) -> None:
        self._call("put_item", TableName=self._table, Item={
            "pk": {"S": f"EVALS#{owner_sub}"}, "sk": {"S": f"{evaluation.model_id}#{evaluation.recorded_at}"},
            "body": {"S": evaluation.model_dump_json()}})

    def for_owner(self, owner_sub: str) -> list[Evaluation]:
        items = all_items(self._client, "query", _SERVICE, TableName=self._table, KeyConditionExpression="pk = :pk",
                          ExpressionAttributeValues={":pk": {"S": f"EVALS#{owner_sub}"}})
        return [Evaluation.model_validate_json(item["body"]["S"]) for item in islice(items, _MOST_EVALUATIONS)]

    def _call(self, operation: str, **kwargs: Any) -> Any:
        return call(self._client, operation, _SERVICE, **kwargs)

