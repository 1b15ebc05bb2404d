"""The in-memory booth store of the fast domain tier (tests/in_memory/booth.py) behaves as DynamoBoothStore does (over
moto) on every point RunService and TrainingService rely on: each assertion here runs against both."""
from __future__ import annotations

from typing import Any

import pytest

from chalicelib.domain.booth_runs import RecordChanged, RunMode, RunRecord, RunStatus
from chalicelib.domain.booth_training import JobStatus, TrainingJob
from tests.in_memory.booth import InMemoryBoothStore

pytestmark = pytest.mark.unit


@pytest.fixture(params=["in_memory", "dynamodb"])
def store(request: pytest.FixtureRequest) -> Any:
    if request.param == "in_memory":
        return InMemoryBoothStore()
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.booth import DynamoBoothStore

    request.getfixturevalue("stack")
    return DynamoBoothStore(clients.dynamodb(), get_settings().table("booth"))


def a_run(run_id: str = "aaaaaaaaaaaa01", owner: str = "alice-sub", created_at: str = "2026-05-14T10:00:00Z",
          status: RunStatus = RunStatus.RECORDING) -> RunRecord:
    return RunRecord(run_id=run_id, owner_sub=owner, owner_username=owner.removesuffix("-sub"), track_id="drem_oval",
                     mode=RunMode.MANUAL, status=status, created_at=created_at, prefix=f"runs/{run_id}/")


def a_job(job_id: str = "bbbbbbbbbbbb01", owner: str = "alice-sub", created_at: str = "2026-05-14T10:00:00Z",
          status: JobStatus = JobStatus.QUEUED) -> TrainingJob:
    return TrainingJob(job_id=job_id, owner_sub=owner, owner_username=owner.removesuffix("-sub"), run_ids=["r1"],
                       track_id="drem_oval", frames=10, epochs=2, status=status, created_at=created_at)


def test_a_run_reads_back_as_written_and_a_missing_one_is_none(store: Any) -> None:
    assert store.get_run("aaaaaaaaaaaa01") is None
    store.create_run(a_run())
    assert store.get_run("aaaaaaaaaaaa01") == a_run()


def test_creating_a_run_id_twice_is_a_change_and_keeps_the_first(store: Any) -> None:
    store.create_run(a_run())
    with pytest.raises(RecordChanged):
        store.create_run(a_run(created_at="2026-05-15T10:00:00Z"))
    assert store.get_run("aaaaaaaaaaaa01").created_at == "2026-05-14T10:00:00Z"


def test_a_run_changes_only_from_the_status_its_writer_read(store: Any) -> None:
    store.create_run(a_run())
    store.replace_run(a_run(status=RunStatus.QUEUED), expected_status="RECORDING")
    assert store.get_run("aaaaaaaaaaaa01").status is RunStatus.QUEUED

    with pytest.raises(RecordChanged):  # a second worker, still holding RECORDING
        store.replace_run(a_run(status=RunStatus.FAILED), expected_status="RECORDING")
    assert store.get_run("aaaaaaaaaaaa01").status is RunStatus.QUEUED
    with pytest.raises(RecordChanged):  # nothing to replace fails the condition too, and creates nothing
        store.replace_run(a_run(run_id="cccccccccccc01"), expected_status="RECORDING")
    assert store.get_run("cccccccccccc01") is None


def test_runs_are_listed_newest_first_per_racer_and_for_everyone(store: Any) -> None:
    store.create_run(a_run("aaaaaaaaaaaa01", created_at="2026-05-14T10:00:00Z"))
    store.create_run(a_run("aaaaaaaaaaaa03", created_at="2026-05-14T12:00:00Z"))
    store.create_run(a_run("aaaaaaaaaaaa02", owner="bob-sub", created_at="2026-05-14T11:00:00Z"))

    assert [r.run_id for r in store.runs_of("alice-sub")] == ["aaaaaaaaaaaa03", "aaaaaaaaaaaa01"]
    assert [r.run_id for r in store.all_runs()] == ["aaaaaaaaaaaa03", "aaaaaaaaaaaa02", "aaaaaaaaaaaa01"]
    assert store.runs_of("nobody-sub") == []


def test_a_job_reads_back_changes_only_from_the_status_read_and_lists_newest_first(store: Any) -> None:
    assert store.get_job("bbbbbbbbbbbb01") is None
    store.create_job(a_job())
    store.create_job(a_job("bbbbbbbbbbbb02", created_at="2026-05-14T11:00:00Z"))
    store.create_job(a_job("bbbbbbbbbbbb03", owner="bob-sub", created_at="2026-05-14T12:00:00Z"))
    assert store.get_job("bbbbbbbbbbbb01") == a_job()
    with pytest.raises(RecordChanged):
        store.create_job(a_job(status=JobStatus.DONE))

    store.replace_job(a_job(status=JobStatus.RUNNING), expected_status="QUEUED")
    with pytest.raises(RecordChanged):  # the worker that died, taking the same job again
        store.replace_job(a_job(status=JobStatus.FAILED), expected_status="QUEUED")
    with pytest.raises(RecordChanged):
        store.replace_job(a_job("bbbbbbbbbbbb09"), expected_status="QUEUED")
    assert store.get_job("bbbbbbbbbbbb01").status is JobStatus.RUNNING
    assert store.get_job("bbbbbbbbbbbb09") is None

    assert [j.job_id for j in store.jobs_of("alice-sub")] == ["bbbbbbbbbbbb02", "bbbbbbbbbbbb01"]
    assert [j.job_id for j in store.all_jobs()] == ["bbbbbbbbbbbb03", "bbbbbbbbbbbb02", "bbbbbbbbbbbb01"]


def test_the_active_version_is_none_until_set_and_a_set_overwrites(store: Any) -> None:
    assert store.active_of("alice-sub") is None
    store.set_active("alice-sub", "m1")
    store.set_active("alice-sub", "m2")
    store.set_active("bob-sub", "m9")
    assert (store.active_of("alice-sub"), store.active_of("bob-sub")) == ("m2", "m9")
