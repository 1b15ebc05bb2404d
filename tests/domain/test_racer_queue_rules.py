"""The rules of a track's racer queue, on the fast domain tier: RacerQueueService over the in-memory queue store
(tests/in_memory/racer_queue.py), no moto and no HTTP. The timekeeper's panel (what is on deck, the form's messages,
who may press the buttons) and starting races from it stay in tests/unit/test_racer_queue.py."""
from __future__ import annotations

from dataclasses import dataclass
from datetime import date

import pytest

from chalicelib.core.errors import Conflict, InvalidInput, NotFound
from chalicelib.core.principals import User
from chalicelib.domain.events import Event, Track
from chalicelib.domain.racer_models import ModelRecord, ModelStatus, ScrutineerResult
from chalicelib.domain.racer_queue import (
    MAX_QUEUE_LENGTH,
    AddToQueue,
    MoveInQueue,
    QueueChanged,
    RacerQueue,
    RacerQueueService,
)
from drem_leaderboard.models import RaceConfig
from tests.in_memory.racer_queue import InMemoryQueueStore

pytestmark = pytest.mark.domain

TIMEKEEPER = User(sub="tk-sub", username="timekeeper", groups=frozenset({"operator"}))
EVENT = Event(event_id="e1", name="Summit", event_type="AWS_SUMMIT", date=date(2026, 5, 14), country_code="SE",
              sponsor="", race_config=RaceConfig(), tracks=(Track(track_id="1"),), landing_page_links=(),
              created_at_ms=1, created_by="op", updated_at_ms=1, version=1)
PASSED = ScrutineerResult(verdict="passed", message="drove 3 laps", track="reinvent_base")


class OneEvent:
    def event(self, event_id: str) -> Event:
        if event_id != EVENT.event_id:
            raise NotFound(f"There is no event {event_id}.")
        return EVENT


@dataclass(frozen=True)
class Racer:
    username: str
    sub: str


class Racers:
    def get_user(self, username: str) -> Racer:
        if username in {"nobody-here", ""}:
            raise NotFound(f"There is no user {username}.", field="racer_username")
        return Racer(username, f"{username}-sub")


class Models:
    """Each racer's models ready to race; `add` puts one more (by default one that passed scrutineering)."""

    def __init__(self) -> None:
        self.records: list[ModelRecord] = []

    def add(self, owner: str, name: str, *, uploaded_at: str = "2026-05-14T09:00:00Z",
            result: ScrutineerResult | None = PASSED) -> ModelRecord:
        record = ModelRecord(model_id=f"{owner}-{name}-{uploaded_at}", owner_sub=f"{owner}-sub", owner_username=owner,
                             name=name, status=ModelStatus.AVAILABLE, uploaded_at=uploaded_at,
                             updated_at=uploaded_at, upload_key="k", s3_key="models/k", scrutineer_result=result)
        self.records.append(record)
        return record

    def available_models_of(self, owner_sub: str) -> list[ModelRecord]:
        return [record for record in self.records if record.owner_sub == owner_sub]


@dataclass
class Desk:
    service: RacerQueueService
    store: InMemoryQueueStore
    models: Models

    def add(self, racer: str, model: str | None = None, *, confirmed: bool = False) -> RacerQueue:
        if model is None:
            model = f"{racer}-model"
            if not self.models.available_models_of(f"{racer}-sub"):
                self.models.add(racer, model)
        return self.service.add(TIMEKEEPER, "e1", "1", AddToQueue(racer_username=racer, model=model,
                                                                  confirmed=confirmed))

    def entry_of(self, racer: str) -> str:
        return next(e.entry_id for e in self.service.queue("e1", "1").entries if e.racer_username == racer)

    def move(self, racer: str, direction: str) -> list[str]:
        return names(self.service.move("e1", "1", MoveInQueue(entry_id=self.entry_of(racer), direction=direction)))

    def line(self) -> list[str]:
        return names(self.service.queue("e1", "1"))


def names(queue: RacerQueue) -> list[str]:
    return [entry.racer_username for entry in queue.entries]


@pytest.fixture
def desk() -> Desk:
    store, models = InMemoryQueueStore(), Models()
    return Desk(RacerQueueService(store, OneEvent(), Racers(), models, clock_ms=lambda: 1_000), store, models)


def test_staff_line_racers_up_reorder_and_take_them_off(desk: Desk) -> None:
    for racer in ("alice", "bob", "carol", "dave"):
        desk.add(racer)
    assert desk.line() == ["alice", "bob", "carol", "dave"]
    assert desk.move("carol", "up") == ["alice", "carol", "bob", "dave"]
    assert desk.move("alice", "down") == ["carol", "alice", "bob", "dave"]
    assert desk.move("carol", "up") == ["carol", "alice", "bob", "dave"]  # the head stays the head
    assert desk.move("dave", "down") == ["carol", "alice", "bob", "dave"]
    assert names(desk.service.remove("e1", "1", desk.entry_of("carol"))) == ["alice", "bob", "dave"]
    assert desk.store.get("e1", "1") is not None and names(desk.store.get("e1", "1")) == desk.line()


def test_a_racer_is_in_the_queue_once_and_the_queue_has_a_limit(desk: Desk) -> None:
    desk.add("alice")
    with pytest.raises(Conflict, match="alice is already in the queue") as twice:
        desk.add("alice")
    assert twice.value.field == "racer_username"
    for index in range(1, MAX_QUEUE_LENGTH):
        desk.add(f"racer{index}")
    with pytest.raises(Conflict, match=f"at most {MAX_QUEUE_LENGTH} racers"):
        desk.add("one-too-many")
    assert len(desk.line()) == MAX_QUEUE_LENGTH


def test_the_racers_model_is_found_by_name_or_id_and_the_newest_upload_wins_a_name(desk: Desk) -> None:
    desk.models.add("alice", "fast", uploaded_at="2026-05-13T09:00:00Z")
    newest = desk.models.add("alice", "fast", uploaded_at="2026-05-14T09:00:00Z")
    desk.models.add("alice", "steady")
    assert desk.add("alice", "fast").entries[0].model_id == newest.model_id
    steady = desk.models.records[2]
    desk.service.remove("e1", "1", desk.entry_of("alice"))
    assert desk.add("alice", steady.model_id).entries[0].model_name == "steady"


def test_an_unknown_racer_or_model_is_refused_and_the_queue_keeps_what_it_had(desk: Desk) -> None:
    desk.add("alice")
    with pytest.raises(NotFound):
        desk.add("nobody-here", "fast")
    desk.models.add("bob", "bob-model")
    with pytest.raises(InvalidInput) as not_theirs:
        desk.add("bob", "alice-model")
    assert str(not_theirs.value) == "bob has no model ready to race named 'alice-model'; their models: bob-model."
    assert not_theirs.value.field == "model"
    with pytest.raises(InvalidInput, match="carol has no model ready to race: they upload one first"):
        desk.add("carol", "anything")
    with pytest.raises(NotFound, match="no longer in the queue"):
        desk.service.remove("e1", "1", "0" * 32)
    with pytest.raises(NotFound, match="has no track '9'"):
        desk.service.queue("e1", "9")
    assert desk.line() == ["alice"]


def test_a_model_that_has_not_passed_scrutineering_is_queued_only_after_staff_say_yes(desk: Desk) -> None:
    desk.models.add("alice", "alice-model", result=None)
    with pytest.raises(Conflict) as asked:
        desk.add("alice", "alice-model")
    assert str(asked.value) == ("alice – alice-model: not scrutineered. On the car it may leave the track or not "
                                "drive at all: add it anyway?")
    assert asked.value.field == "confirm"
    assert desk.line() == [], "nothing reaches the queue (and so no car) before the answer"
    desk.add("alice", "alice-model", confirmed=True)
    assert desk.line() == ["alice"]


def test_two_screens_changing_the_queue_at_once_lose_neither_change(desk: Desk) -> None:
    desk.add("alice")
    desk.add("bob")
    bob, real_put, raced = desk.entry_of("bob"), desk.store.put, []

    def put_after_another_screen(queue: RacerQueue, *, expected_version: int) -> None:
        if not raced:  # the other tablet takes bob off between this change's read and its write
            raced.append(True)
            current = desk.store.get("e1", "1")
            assert current is not None
            real_put(current.model_copy(update={"entries": [e for e in current.entries if e.entry_id != bob],
                                                "version": current.version + 1}), expected_version=current.version)
        real_put(queue, expected_version=expected_version)

    desk.store.put = put_after_another_screen  # type: ignore[method-assign]
    assert desk.move("alice", "down") == ["alice"] and raced  # the stale write was refused and the move re-applied
    assert desk.line() == ["alice"]


def test_a_queue_that_keeps_changing_underneath_is_a_conflict_not_a_lost_change(desk: Desk) -> None:
    desk.add("alice")
    desk.add("bob")

    def always_changed(queue: RacerQueue, *, expected_version: int) -> None:
        raise QueueChanged(queue.track_id)

    desk.store.put = always_changed  # type: ignore[method-assign]
    with pytest.raises(Conflict, match="changing right now"):
        desk.move("alice", "down")


def test_a_starting_race_is_recorded_once_on_its_entry(desk: Desk) -> None:
    desk.add("alice")
    entry = desk.entry_of("alice")
    assert desk.service.mark_starting("e1", "1", entry, "race-1").starting_race_id == "race-1"
    assert desk.service.mark_starting("e1", "1", entry, "race-2").starting_race_id == "race-1"
    queue = desk.service.set_car("e1", "1", entry, "car-01")
    assert (queue.entries[0].car, queue.entries[0].starting_race_id) == ("car-01", "race-1")
    assert names(desk.service.remove("e1", "1", "gone", missing_ok=True)) == ["alice"]
