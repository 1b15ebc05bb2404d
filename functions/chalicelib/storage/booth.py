"""DynamoDB adapter for the learning booth (table `booth`): runs, training jobs and each racer's active model version.

Items (body = the record as JSON; `status` and `owner` repeated as attributes for conditions):
- a run: `RUN#{runId}` / `RUN`, gsi1 `RUNS#{ownerSub}` / `{createdAt}#{runId}`, gsi2 `RUNS` / `{createdAt}#{runId}`;
- a training job: `JOB#{jobId}` / `JOB`, gsi1 `JOBS#{ownerSub}` / `{createdAt}#{jobId}`, gsi2 `JOBS` / same;
- the active version: `ACTIVE#{ownerSub}` / `ACTIVE`, attribute `model_id`.
Status changes are conditional on the status the caller read, so two workers (or a worker and a racer) can never
both move the same job or run: the loser gets `RecordChanged`.
"""
from __future__ import annotations

from collections.abc import Iterator
from itertools import islice
from typing import Any

from botocore.exceptions import BotoCoreError, ClientError

from chalicelib.domain.booth_runs import RecordChanged, RunRecord
from chalicelib.domain.booth_training import TrainingJob
from chalicelib.storage.aws_errors import all_items, call, error_code, translate_common

_SERVICE = "The booth store"
_CONDITION_FAILED = "ConditionalCheckFailedException"
_MOST_LISTED = 500  # a bound on one listing, whatever a runaway client created


class DynamoBoothStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    # -- runs --------------------------------------------------------------------------------------------------------

    def create_run(self, run: RunRecord) -> None:
        self._put(_run_item(run), new=True)

    def replace_run(self, run: RunRecord, *, expected_status: str) -> None:
        self._put(_run_item(run), expected_status=expected_status)

    def get_run(self, run_id: str) -> RunRecord | None:
        item = self._get(f"RUN#{run_id}", "RUN")
        return RunRecord.model_validate_json(item["body"]["S"]) if item else None

    def runs_of(self, owner_sub: str) -> list[RunRecord]:
        return [RunRecord.model_validate_json(i["body"]["S"]) for i in self._index("gsi1", f"RUNS#{owner_sub}")]

    def all_runs(self) -> list[RunRecord]:
        return [RunRecord.model_validate_json(i["body"]["S"]) for i in self._index("gsi2", "RUNS")]

    # -- training jobs -----------------------------------------------------------------------------------------------

    def create_job(self, job: TrainingJob) -> None:
        self._put(_job_item(job), new=True)

    def replace_job(self, job: TrainingJob, *, expected_status: str) -> None:
        self._put(_job_item(job), expected_status=expected_status)

    def get_job(self, job_id: str) -> TrainingJob | None:
        item = self._get(f"JOB#{job_id}", "JOB")
        return TrainingJob.model_validate_json(item["body"]["S"]) if item else None

    def jobs_of(self, owner_sub: str) -> list[TrainingJob]:
        return [TrainingJob.model_validate_json(i["body"]["S"]) for i in self._index("gsi1", f"JOBS#{owner_sub}")]

    def all_jobs(self) -> list[TrainingJob]:
        return [TrainingJob.model_validate_json(i["body"]["S"]) for i in self._index("gsi2", "JOBS")]

    # -- the active version ------------------------------------------------------------------------------------------

    def set_active(self, owner_sub: str, model_id: str) -> None:
        call(self._client, "put_item", _SERVICE, TableName=self._table, Item={
            "pk": {"S": f"ACTIVE#{owner_sub}"}, "sk": {"S": "ACTIVE"}, "model_id": {"S": model_id}})

    def active_of(self, owner_sub: str) -> str | None:
        item = self._get(f"ACTIVE#{owner_sub}", "ACTIVE")
        return item["model_id"]["S"] if item else None

    # -- plumbing ----------------------------------------------------------------------------------------------------

    def _get(self, pk: str, sk: str) -> dict[str, Any] | None:
        answer = call(self._client, "get_item", _SERVICE, TableName=self._table,
                      Key={"pk": {"S": pk}, "sk": {"S": sk}}, ConsistentRead=True)
        return answer.get("Item")

    def _index(self, index: str, partition: str) -> Iterator[dict[str, Any]]:
        items = all_items(self._client, "query", _SERVICE, TableName=self._table, IndexName=index,
                          KeyConditionExpression=f"{index}pk = :pk",
                          ExpressionAttributeValues={":pk": {"S": partition}}, ScanIndexForward=False)
        return islice(items, _MOST_LISTED)

    def _put(self, item: dict[str, Any], *, new: bool = False, expected_status: str | None = None) -> None:
        condition: dict[str, Any] = {}
        if new:
            condition = {"ConditionExpression": "attribute_not_exists(pk)"}
        elif expected_status is not None:
            condition = {"ConditionExpression": "#status = :expected",
                         "ExpressionAttributeNames": {"#status": "status"},
                         "ExpressionAttributeValues": {":expected": {"S": expected_status}}}
        try:
            self._client.put_item(TableName=self._table, Item=item, **condition)
        except ClientError as exc:
            if error_code(exc) == _CONDITION_FAILED:
                raise RecordChanged("someone else changed this first") from None
            raise translate_common(exc, _SERVICE, write=True) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, _SERVICE, write=True) from exc


def _run_item(run: RunRecord) -> dict[str, Any]:
    order = f"{run.created_at}#{run.run_id}"
    return {"pk": {"S": f"RUN#{run.run_id}"}, "sk": {"S": "RUN"}, "status": {"S": run.status.value},
            "gsi1pk": {"S": f"RUNS#{run.owner_sub}"}, "gsi1sk": {"S": order}, "gsi2pk": {"S": "RUNS"},
            "gsi2sk": {"S": order}, "body": {"S": run.model_dump_json()}}


def _job_item(job: TrainingJob) -> dict[str, Any]:
    order = f"{job.created_at}#{job.job_id}"
    return {"pk": {"S": f"JOB#{job.job_id}"}, "sk": {"S": "JOB"}, "status": {"S": job.status.value},
            "gsi1pk": {"S": f"JOBS#{job.owner_sub}"}, "gsi1sk": {"S": order}, "gsi2pk": {"S": "JOBS"},
            "gsi2sk": {"S": order}, "body": {"S": job.model_dump_json()}}
