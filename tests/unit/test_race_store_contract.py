"""The in-memory race store of the fast domain tier (tests/in_memory/races.py) behaves as DynamoRaceStore does (over
moto) on every point RaceService and TimingService rely on: each assertion here runs against both."""
from __future__ import annotations

from typing import Any

import pytest

from chalicelib.core.errors import Conflict
from chalicelib.domain.race_writes import StaleRace
from chalicelib.domain.races import PublishIntent, RaceRecord
from drem_leaderboard.models import Race, RaceConfig, Racer, RaceStatus
from tests.in_memory.races import InMemoryRaceStore

pytestmark = pytest.mark.unit


@pytest.fixture(params=["in_memory", "dynamodb"])
def store(request: pytest.FixtureRequest) -> Any:
    if request.param == "in_memory":
        return InMemoryRaceStore()
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.races import DynamoRaceStore

    request.getfixturevalue("stack")
    return DynamoRaceStore(clients.dynamodb(), get_settings().table("races"))


def a_race(race_id: str = "r1", version: int = 0, track_id: str = "1", racer: str = "alice", event_id: str = "e1",
           status: RaceStatus = RaceStatus.READY) -> RaceRecord:
    race = Race(race_id=race_id, event_id=event_id, track_id=track_id, racer=Racer(sub=f"{racer}-sub", username=racer),
                config=RaceConfig(), status=status, created_at_ms=1, version=version)
    return RaceRecord(race=race, created_by="op")


def test_a_live_race_reads_back_and_holds_its_track(store: Any) -> None:
    assert store.get("e1", "r1") is None and store.live_race_id("e1", "1") is None
    store.create_live(a_race())
    assert store.get("e1", "r1") == a_race()
    assert (store.live_race_id("e1", "1"), store.live_racer("e1", "1")) == ("r1", "alice")
    assert store.live_race_id("e1", "2") is None


def test_a_second_live_race_on_a_track_is_a_conflict_naming_the_racer_and_stores_nothing(store: Any) -> None:
    store.create_live(a_race())
    with pytest.raises(Conflict, match=r"Track 1 already has a live race \(alice\)"):
        store.create_live(a_race("r2", racer="bob"))
    assert store.get("e1", "r2") is None
    assert store.live_race_id("e1", "1") == "r1"
    store.create_live(a_race("r3", track_id="2", racer="bob"))  # another track is free
    assert store.live_racer("e1", "2") == "bob"


def test_a_save_needs_the_stored_version(store: Any) -> None:
    store.create_live(a_race())
    store.save(a_race(version=1, status=RaceStatus.RUNNING), expected_version=0)
    assert store.get("e1", "r1").race.status is RaceStatus.RUNNING

    with pytest.raises(StaleRace):  # a second writer, still on version 0
        store.save(a_race(version=1, status=RaceStatus.PAUSED), expected_version=0)
    assert store.get("e1", "r1").race.status is RaceStatus.RUNNING
    with pytest.raises(StaleRace):  # a race that is not stored fails the condition too
        store.save(a_race("nope", version=1), expected_version=0)
    assert store.get("e1", "nope") is None


def test_finalising_frees_the_track_and_a_stale_finalise_changes_nothing(store: Any) -> None:
    store.create_live(a_race())
    with pytest.raises(StaleRace):
        store.finalise(a_race(version=2, status=RaceStatus.SUBMITTED), expected_version=1)
    assert store.live_race_id("e1", "1") == "r1"

    store.finalise(a_race(version=1, status=RaceStatus.SUBMITTED), expected_version=0)
    assert store.get("e1", "r1").race.status is RaceStatus.SUBMITTED
    assert store.live_race_id("e1", "1") is None
    with pytest.raises(StaleRace):  # the pointer is gone: finalising again is refused
        store.finalise(a_race(version=2, status=RaceStatus.DISCARDED), expected_version=1)
    assert store.get("e1", "r1").race.status is RaceStatus.SUBMITTED


def test_races_are_listed_per_event_by_id_with_filters_and_per_racer(store: Any) -> None:
    store.create_live(a_race("r2"))
    store.create_live(a_race("r1", track_id="2", racer="bob"))
    store.create_live(a_race("r3", event_id="e2"))

    assert [r.race.race_id for r in store.list_event("e1")] == ["r1", "r2"]
    assert [r.race.race_id for r in store.list_event("e1", track_id="1")] == ["r2"]
    assert [r.race.race_id for r in store.list_event("e1", racer_sub="bob-sub")] == ["r1"]
    assert store.list_event("e1", track_id="2", racer_sub="alice-sub") == []
    assert sorted((r.race.event_id, r.race.race_id) for r in store.list_racer("alice-sub")) == [("e1", "r2"),
                                                                                                ("e2", "r3")]


def test_a_strip_outcome_is_stored_once_with_its_race(store: Any) -> None:
    store.create_live(a_race())
    assert store.save_with_outcome(a_race(version=1, status=RaceStatus.RUNNING), 0, "timer-1", "k1", '{"n": 1}')
    assert store.get_outcome("timer-1", "k1") == '{"n": 1}'
    assert store.get("e1", "r1").race.version == 1

    # the same key again (a retried post): nothing is written, the caller replays the stored outcome
    assert not store.save_with_outcome(a_race(version=2, status=RaceStatus.PAUSED), 1, "timer-1", "k1", '{"n": 2}')
    assert store.get_outcome("timer-1", "k1") == '{"n": 1}'
    assert store.get("e1", "r1").race.version == 1

    with pytest.raises(StaleRace):  # a new key on a race that moved meanwhile: neither is stored
        store.save_with_outcome(a_race(version=2), 0, "timer-1", "k2", '{"n": 3}')
    assert store.get_outcome("timer-1", "k2") is None
    assert store.save_with_outcome(None, None, "timer-1", "k3", '{"ignored": true}')  # an outcome without a race
    assert store.get_outcome("timer-1", "k3") == '{"ignored": true}'
    assert store.get_outcome("timer-2", "k1") is None


def test_every_race_write_leaves_its_racers_intent_until_that_write_is_published(store: Any) -> None:
    store.create_live(a_race())
    created = PublishIntent.of(a_race().race)
    assert store.pending_publishes() == [created]

    store.save(a_race(version=1), expected_version=0)
    store.complete_publish(created)  # an older write's intent never drops the newer one
    newer = PublishIntent.of(a_race(version=1).race)
    assert store.pending_publishes() == [newer]
    assert store.pending_publishes(older_than_ms=60_000) == []  # written just now: someone is publishing it

    store.complete_publish(newer)
    assert store.pending_publishes() == []
    store.delete(a_race(version=1))
    assert store.get("e1", "r1") is None
    assert store.pending_publishes() == [PublishIntent.of(a_race(version=1).race, deleted=True)]
