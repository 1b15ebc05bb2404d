"""The rules of the learning booth's runs, on the fast domain tier: RunService over the in-memory booth store
(tests/in_memory/booth.py), no moto and no HTTP. Uploading artifacts, finalising, live drives and the 429 a racer
gets over the API stay in tests/unit/test_booth_api.py (they cross the runs bucket and HTTP)."""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from chalicelib.core.errors import Forbidden, NotFound, RateLimited
from chalicelib.core.principals import User
from chalicelib.domain.booth_runs import MAX_OPEN_RUNS, OPEN_WINDOW_S, ListRunsQuery, NewRun, RunService, RunStatus
from chalicelib.domain.booth_tracks import TrackService
from tests.in_memory.booth import InMemoryBoothStore

pytestmark = pytest.mark.domain

ALICE = User(sub="alice-sub", username="alice", groups=frozenset({"racer"}))
BOB = User(sub="bob-sub", username="bob", groups=frozenset({"racer"}))
OPERATOR = User(sub="op-sub", username="op", groups=frozenset({"operator"}))
COMMENTATOR = User(sub="kim-sub", username="kim", groups=frozenset({"commentator"}))


class NotTouched:
    """The runs bucket and the model service: manual runs are created, listed and read without them."""

    def __getattr__(self, name: str) -> Any:
        raise AssertionError(f"a manual run's {name} needs no files or models")


class Clock:
    """UTC timestamps as RunService writes them, a second apart unless moved on."""

    def __init__(self) -> None:
        self.seconds = 0

    def __call__(self) -> str:
        self.seconds += 1
        hours, rest = divmod(self.seconds, 3600)
        return f"2026-05-{14 + hours // 24:02d}T{hours % 24:02d}:{rest // 60:02d}:{rest % 60:02d}.000000Z"


@pytest.fixture
def booth() -> Iterator[tuple[RunService, Clock]]:
    clock, ids = Clock(), iter(range(1, 10**6))
    service = RunService(InMemoryBoothStore(), NotTouched(), TrackService(), NotTouched(),  # type: ignore[arg-type]
                         clock=clock, new_id=lambda: f"{next(ids):012x}aa")
    yield service, clock


def manual(track_id: str = "drem_oval") -> NewRun:
    return NewRun(track_id=track_id)


def test_a_racer_may_hold_only_a_few_open_runs_and_the_limit_is_theirs(booth: tuple[RunService, Clock]) -> None:
    runs, _ = booth
    for _ in range(MAX_OPEN_RUNS):
        runs.create(ALICE, manual())
    with pytest.raises(RateLimited, match=f"You have {MAX_OPEN_RUNS} runs started in the last hour"):
        runs.create(ALICE, manual())
    assert runs.create(BOB, manual()).status is RunStatus.RECORDING  # a limit per racer
    assert len(runs.list_runs(ALICE, ListRunsQuery())) == MAX_OPEN_RUNS


def test_open_runs_older_than_the_window_no_longer_count(booth: tuple[RunService, Clock]) -> None:
    runs, clock = booth
    for _ in range(MAX_OPEN_RUNS):
        runs.create(ALICE, manual())
    clock.seconds += OPEN_WINDOW_S + 1  # drives lost to a restart an hour ago
    assert runs.create(ALICE, manual()).owner_username == "alice"


def test_an_unknown_track_is_not_found_and_stores_no_run(booth: tuple[RunService, Clock]) -> None:
    runs, _ = booth
    with pytest.raises(NotFound, match="There is no track 'nowhere'"):
        runs.create(ALICE, manual("nowhere"))
    assert runs.list_runs(ALICE, ListRunsQuery()) == []


def test_a_racer_sees_their_own_runs_and_model_staff_see_everyones(booth: tuple[RunService, Clock]) -> None:
    runs, _ = booth
    alices = runs.create(ALICE, manual())
    bobs = runs.create(BOB, manual())

    assert runs.get(ALICE, alices.run_id) == alices
    assert runs.get(OPERATOR, alices.run_id) == alices
    with pytest.raises(Forbidden):
        runs.get(BOB, alices.run_id)
    with pytest.raises(Forbidden):
        runs.get(COMMENTATOR, alices.run_id)
    assert [r.run_id for r in runs.list_runs(ALICE, ListRunsQuery(everyone=True))] == [alices.run_id]
    assert [r.run_id for r in runs.list_runs(OPERATOR, ListRunsQuery(everyone=True))] == [bobs.run_id,
                                                                                          alices.run_id]
