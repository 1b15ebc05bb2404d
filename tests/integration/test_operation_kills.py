"""kill -9 of the real processes inside a queue start, `drem import` and a booth training job, at a point on the
storage journal (tests/chaos_operations.py; the storage server's kill point), then `drem up`'s supervisor restarts
them and the user repeats what got no answer: one race and a shorter queue; an import that finishes with its groups,
its passwords shown, its audit entry once and no resume file left; a booth visitor's training job whose trainer
worker was killed midway ends DONE with exactly one new version, its archive stored, one finished autonomous run.
The chaos bench (bench/chaos.py) runs the same rounds with the kill point drawn over every record of each operation,
and the other operations."""
from __future__ import annotations

import pytest

from tests.chaos_harness import Chaos
from tests.chaos_operations import OperationKills

pytestmark = [pytest.mark.integration, pytest.mark.durability]


@pytest.fixture(scope="module")
def kills(tmp_path_factory: pytest.TempPathFactory, monkeypatch_module):
    monkeypatch_module.setenv("DREM_CHECK_STALE_AFTER_S", "5")
    work = tmp_path_factory.mktemp("operation-kills")
    chaos = Chaos(work / "state", seed=29)
    try:
        chaos.start(racing=False)
        campaign = OperationKills(chaos, work)
        yield campaign
        campaign.close()
    finally:
        chaos.close()


@pytest.fixture(scope="module")
def monkeypatch_module():
    with pytest.MonkeyPatch.context() as patch:
        yield patch


def _assert_whole(kills: OperationKills, operation: str) -> None:
    figures = kills.figures[operation]
    assert figures.killed == figures.runs == 1, f"the kill point never fired: {figures.line()}"
    assert figures.clean, f"{figures.line()}: {figures.problems}"


def test_storage_killed_as_the_race_of_a_queue_start_reaches_the_journal_ends_in_one_race_and_a_shorter_queue(kills):
    kills.run("queue start", "storage", at_record=2)  # the entry marked starting, then the race: cut there
    _assert_whole(kills, "queue start")


def test_drem_import_and_the_stack_killed_midway_are_finished_by_running_the_import_again(kills):
    kills.run("import", "everything", at_record=9)  # of its ~18: accounts made, their groups and the event not yet
    _assert_whole(kills, "import")


def test_the_trainer_worker_killed_midway_through_a_visitors_training_job_finishes_it_with_one_version(kills):
    kills.run("booth training", "worker", at_record=12)  # of its ~31: the version submitted, not yet raced
    _assert_whole(kills, "booth training")
