"""The learning booth's runs, training jobs and active versions in memory: the ports RunService (RunStore) and
TrainingService (JobStore) take.

Copies chalicelib/storage/booth.py (DynamoBoothStore): records are kept as their JSON, so a read never hands out the
stored object; `create_*` is conditional on the id being free (`attribute_not_exists(pk)`) and `replace_*` on the
stored status being the one the caller read (`#status = :expected`, which a missing record fails too), and a failed
condition raises RecordChanged, storing nothing; listings come newest first (the index's sort key
`{createdAt}#{id}`, read backwards) and stop at 500; `set_active` overwrites.
"""
from __future__ import annotations

from typing import TypeVar

from chalicelib.domain.booth_runs import RecordChanged, RunRecord
from chalicelib.domain.booth_training import TrainingJob

Record = TypeVar("Record", RunRecord, TrainingJob)

MOST_LISTED = 500  # storage/booth.py's bound on one listing


class InMemoryBoothStore:
    def __init__(self) -> None:
        self._runs: dict[str, str] = {}  # run id -> the record's JSON
        self._jobs: dict[str, str] = {}  # job id -> the job's JSON
        self._active: dict[str, str] = {}  # owner sub -> model id

    # -- runs --
    def create_run(self, run: RunRecord) -> None:
        if run.run_id in self._runs:
            raise RecordChanged("someone else changed this first")
        self._runs[run.run_id] = run.model_dump_json()

    def replace_run(self, run: RunRecord, *, expected_status: str) -> None:
        stored = self.get_run(run.run_id)
        if stored is None or stored.status.value != expected_status:
            raise RecordChanged("someone else changed this first")
        self._runs[run.run_id] = run.model_dump_json()

    def get_run(self, run_id: str) -> RunRecord | None:
        found = self._runs.get(run_id)
        return RunRecord.model_validate_json(found) if found else None

    def runs_of(self, owner_sub: str) -> list[RunRecord]:
        return self._newest_first([r for r in self._all(self._runs, RunRecord) if r.owner_sub == owner_sub])

    def all_runs(self) -> list[RunRecord]:
        return self._newest_first(self._all(self._runs, RunRecord))

    # -- training jobs --
    def create_job(self, job: TrainingJob) -> None:
        if job.job_id in self._jobs:
            raise RecordChanged("someone else changed this first")
        self._jobs[job.job_id] = job.model_dump_json()

    def replace_job(self, job: TrainingJob, *, expected_status: str) -> None:
        stored = self.get_job(job.job_id)
        if stored is None or stored.status.value != expected_status:
            raise RecordChanged("someone else changed this first")
        self._jobs[job.job_id] = job.model_dump_json()

    def get_job(self, job_id: str) -> TrainingJob | None:
        found = self._jobs.get(job_id)
        return TrainingJob.model_validate_json(found) if found else None

    def jobs_of(self, owner_sub: str) -> list[TrainingJob]:
        return self._newest_first([j for j in self._all(self._jobs, TrainingJob) if j.owner_sub == owner_sub])

    def all_jobs(self) -> list[TrainingJob]:
        return self._newest_first(self._all(self._jobs, TrainingJob))

    # -- the active version --
    def set_active(self, owner_sub: str, model_id: str) -> None:
        self._active[owner_sub] = model_id

    def active_of(self, owner_sub: str) -> str | None:
        return self._active.get(owner_sub)

    @staticmethod
    def _all(docs: dict[str, str], model: type[Record]) -> list[Record]:
        return [model.model_validate_json(doc) for doc in docs.values()]

    @staticmethod
    def _newest_first(records: list[Record]) -> list[Record]:
        """The index order, `{createdAt}#{id}` backwards, bounded as one listing of the adapter is."""
        return sorted(records, key=lambda r: f"{r.created_at}#{_id_of(r)}", reverse=True)[:MOST_LISTED]


def _id_of(record: RunRecord | TrainingJob) -> str:
    return record.run_id if isinstance(record, RunRecord) else record.job_id
