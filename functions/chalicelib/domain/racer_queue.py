"""The racer queue of a track ("on deck"): staff line racers up, each with the model they will race, and the
timekeeper starts the head's race in one click.

DREM has no queue: its timekeeper wizard walks racer → car → model → upload → race for each racer, so the model
uploads while everyone waits (drem-features.md §3.1). Here the queue is one item per track holding the ordered
entries and a `version`; every change is a conditional write on that version, retried a few times on a clash, so two
tablets editing the queue never lose each other's change.

What an entry's car is for: `OnDeck` (domain/on_deck.py) gives the head's model to a free car of the track's fleet
and records that car here, so starting the race knows which car holds the racer's model.
"""
from __future__ import annotations

import uuid
from collections.abc import Callable
from typing import Literal, Protocol

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.core.errors import Conflict, InvalidInput, NotFound
from chalicelib.core.principals import User
from chalicelib.domain.events import Event
from chalicelib.domain.model_scrutiny import scrutiny_doubt
from chalicelib.domain.racer_models import ModelRecord

MAX_QUEUE_LENGTH = 50
WRITE_ATTEMPTS = 3


class QueueEntry(BaseModel):
    model_config = ConfigDict(frozen=True)
    entry_id: str
    racer_username: str
    racer_sub: str
    model_id: str
    model_name: str
    added_by: str
    added_at_ms: int
    car: str | None = Field(default=None, description="the car given this racer's model (on deck), if any")
    preload_problem: str | None = Field(default=None, description="why the model could not be given to a car")
    starting_race_id: str | None = Field(default=None, description=(
        "the race Start is creating for this entry: written before the race, so after a crash the next Start (or "
        "look at the queue) finds that race instead of creating a second one"))


class RacerQueue(BaseModel):
    model_config = ConfigDict(frozen=True)
    event_id: str
    track_id: str
    entries: list[QueueEntry] = Field(default_factory=list)
    version: int = 0

    @property
    def head(self) -> QueueEntry | None:
        return self.entries[0] if self.entries else None

    def index_of(self, entry_id: str) -> int:
        for index, entry in enumerate(self.entries):
            if entry.entry_id == entry_id:
                return index
        raise NotFound("That racer is no longer in the queue (someone else changed it); the page shows it now.",
                       field="entry_id")


class AddToQueue(BaseModel):
    model_config = ConfigDict(extra="forbid")
    racer_username: str = Field(min_length=1, max_length=128)
    model: str = Field(min_length=1, max_length=200, description="the racer's model: its name or its id")
    confirmed: bool = Field(default=False, description="add it even though the model has not passed scrutineering")


class QueueEntryRef(BaseModel):
    """A button on a queue row (remove, start): which entry it was drawn for."""
    model_config = ConfigDict(extra="forbid")
    entry_id: str = Field(min_length=1, max_length=64)


class MoveInQueue(BaseModel):
    model_config = ConfigDict(extra="forbid")
    entry_id: str = Field(min_length=1, max_length=64)
    direction: Literal["up", "down"]


class QueueChanged(Exception):
    """The queue item changed between read and write (the store raises it); read again and retry."""


class QueueStore(Protocol):
    def get(self, event_id: str, track_id: str) -> RacerQueue | None: ...
    def put(self, queue: RacerQueue, *, expected_version: int) -> None: ...


class EventLookup(Protocol):
    def event(self, event_id: str) -> Event: ...  # raises NotFound


class Racer(Protocol):
    @property
    def username(self) -> str: ...
    @property
    def sub(self) -> str: ...


class RacerLookup(Protocol):
    def get_user(self, username: str) -> Racer: ...  # raises NotFound


class ModelLookup(Protocol):
    def available_models_of(self, owner_sub: str) -> list[ModelRecord]: ...


class RacerQueueService:
    def __init__(self, store: QueueStore, events: EventLookup, racers: RacerLookup, models: ModelLookup,
                 clock_ms: Callable[[], int]) -> None:
        self._store = store
        self._events = events
        self._racers = racers
        self._models = models
        self._clock_ms = clock_ms

    def queue(self, event_id: str, track_id: str) -> RacerQueue:
        self._events.event(event_id).track(track_id)
        return self._store.get(event_id, track_id) or RacerQueue(event_id=event_id, track_id=track_id)

    def add(self, principal: User, event_id: str, track_id: str, data: AddToQueue) -> RacerQueue:
        self._events.event(event_id).track(track_id)
        racer = self._racers.get_user(data.racer_username)
        username, sub = racer.username, racer.sub
        model = self._racer_model(data.model.strip(), username, sub)
        doubt = None if data.confirmed else scrutiny_doubt(model)
        if doubt:  # the head's model goes to a car by itself: ask before, never refuse
            raise Conflict(f"{doubt}. On the car it may leave the track or not drive at all: add it anyway?",
                           field="confirm")
        entry = QueueEntry(entry_id=uuid.uuid4().hex, racer_username=username, racer_sub=sub,
                           model_id=model.model_id, model_name=model.name, added_by=principal.username,
                           added_at_ms=self._clock_ms())

        def appended(queue: RacerQueue) -> list[QueueEntry]:
            if any(e.racer_sub == sub for e in queue.entries):
                raise Conflict(f"{username} is already in the queue.", field="racer_username")
            if len(queue.entries) >= MAX_QUEUE_LENGTH:
                raise Conflict(f"The queue holds at most {MAX_QUEUE_LENGTH} racers.", field="racer_username")
            return [*queue.entries, entry]
        return self._change(event_id, track_id, appended)

    def move(self, event_id: str, track_id: str, data: MoveInQueue) -> RacerQueue:
        def moved(queue: RacerQueue) -> list[QueueEntry]:
            index = queue.index_of(data.entry_id)
            other = index - 1 if data.direction == "up" else index + 1
            entries = list(queue.entries)
            if 0 <= other < len(entries):
                entries[index], entries[other] = entries[other], entries[index]
            return entries
        return self._change(event_id, track_id, moved)

    def remove(self, event_id: str, track_id: str, entry_id: str, *, missing_ok: bool = False) -> RacerQueue:
        def removed(queue: RacerQueue) -> list[QueueEntry]:
            if missing_ok and all(e.entry_id != entry_id for e in queue.entries):
                return list(queue.entries)
            index = queue.index_of(entry_id)
            return [*queue.entries[:index], *queue.entries[index + 1:]]
        return self._change(event_id, track_id, removed)

    def mark_starting(self, event_id: str, track_id: str, entry_id: str, race_id: str) -> QueueEntry:
        """Record on the entry the race about to be created for it (kept if one is recorded already); returns the
        entry as stored. Raises NotFound if the entry left the queue."""
        def marked(queue: RacerQueue) -> list[QueueEntry]:
            entry = queue.entries[queue.index_of(entry_id)]
            if entry.starting_race_id:
                return list(queue.entries)
            return [e.model_copy(update={"starting_race_id": race_id}) if e.entry_id == entry_id else e
                    for e in queue.entries]
        queue = self._change(event_id, track_id, marked)
        return queue.entries[queue.index_of(entry_id)]

    def set_car(self, event_id: str, track_id: str, entry_id: str, car: str | None,
                problem: str | None = None) -> RacerQueue:
        """Record which car holds the entry's model (or why none does); a no-op if the entry left the queue."""
        def updated(queue: RacerQueue) -> list[QueueEntry]:
            return [e.model_copy(update={"car": car, "preload_problem": problem}) if e.entry_id == entry_id else e
                    for e in queue.entries]
        return self._change(event_id, track_id, updated)

    def _racer_model(self, wanted: str, username: str, sub: str) -> ModelRecord:
        """The racer's AVAILABLE model named (or with the id) `wanted`; the newest upload wins a name clash."""
        models = sorted(self._models.available_models_of(sub), key=lambda m: m.uploaded_at, reverse=True)
        model = next((m for m in models if wanted in (m.model_id, m.name)), None)
        if model is not None:
            return model
        if not models:
            raise InvalidInput(f"{username} has no model ready to race: they upload one first (only models that "
                               "passed the checks can go on a car).", field="model")
        names = ", ".join(sorted({m.name for m in models}))
        raise InvalidInput(f"{username} has no model ready to race named {wanted!r}; their models: {names}.",
                           field="model")

    def _change(self, event_id: str, track_id: str,
                change: Callable[[RacerQueue], list[QueueEntry]]) -> RacerQueue:
        self._events.event(event_id).track(track_id)
        for _attempt in range(WRITE_ATTEMPTS):
            current = self._store.get(event_id, track_id) or RacerQueue(event_id=event_id, track_id=track_id)
            entries = change(current)
            if entries == current.entries:
                return current
            updated = current.model_copy(update={"entries": entries, "version": current.version + 1})
            try:
                self._store.put(updated, expected_version=current.version)
                return updated
            except QueueChanged:
                continue
        raise Conflict("The queue is changing right now; try again.", field="entry_id")
