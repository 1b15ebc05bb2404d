"""On deck: the head of a track's racer queue gets their model on a free car while the current race runs, and the
timekeeper starts the head's race on that car in one click.

A free car is a car of the track's fleet that is not the live race's car. The model goes to it through the one
assignment path staff use (`AssignmentService.assign`, what `PUT /api/cars/{id}/models` does): the car agent polls
its assignment, downloads, verifies and loads it, and reports the loaded model in its heartbeat. The model is put
FIRST in the car's list because a car drives the first assigned model that loads (cars/drem_cars/agent.py
`sync_models`); the car's other models stay assigned (up to `MAX_MODELS_PER_CAR`), so nobody else's upload is lost.
"""
from __future__ import annotations

import uuid
from typing import Any, Protocol

from chalicelib.core.errors import Conflict, DremError
from chalicelib.core.principals import User
from chalicelib.domain.assignments import MAX_MODELS_PER_CAR, Assignment, AssignmentService
from chalicelib.domain.devices import DeviceKind, DeviceService, DeviceView
from chalicelib.domain.racer_queue import AddToQueue, MoveInQueue, QueueEntry, RacerQueue, RacerQueueService
from chalicelib.domain.races import CreateRaceInput, RaceService

NO_FREE_CAR = ("No free car in this track's fleet: every car is racing or the fleet has none. Give the model to a "
               "car by hand (Cars), or start the race without a car.")


class LiveRacePointer(Protocol):
    def live_race_id(self, event_id: str, track_id: str) -> str | None: ...


class OnDeck:
    def __init__(self, queue: RacerQueueService, races: RaceService, live: LiveRacePointer, devices: DeviceService,
                 assignments: AssignmentService) -> None:
        self._queue = queue
        self._races = races
        self._live = live
        self._devices = devices
        self._assignments = assignments

    # --- the queue, as staff change it: every change gives the (maybe new) head's model to a free car ---

    def queue(self, event_id: str, track_id: str) -> RacerQueue:
        return self._queue.queue(event_id, track_id)

    def add(self, principal: User, event_id: str, track_id: str, data: AddToQueue) -> RacerQueue:
        self._queue.add(principal, event_id, track_id, data)
        return self.preload_head(principal, event_id, track_id)

    def move(self, principal: User, event_id: str, track_id: str, data: MoveInQueue) -> RacerQueue:
        self._queue.move(event_id, track_id, data)
        return self.preload_head(principal, event_id, track_id)

    def remove(self, principal: User, event_id: str, track_id: str, entry_id: str) -> RacerQueue:
        self._queue.remove(event_id, track_id, entry_id)
        return self.preload_head(principal, event_id, track_id)

    # --- cars ---

    def race_live(self, event_id: str, track_id: str) -> bool:
        return self._live.live_race_id(event_id, track_id) is not None

    def racing_car(self, event_id: str, track_id: str) -> str | None:
        race_id = self._live.live_race_id(event_id, track_id)
        return self._races.record(event_id, race_id).race.car if race_id else None

    def fleet_cars(self, event_id: str, track_id: str) -> list[DeviceView]:
        track = self._races.event(event_id).track(track_id)
        if not track.fleet_id:
            return []
        return [d for d in self._devices.list_devices(fleet_id=track.fleet_id) if d.kind is DeviceKind.CAR]

    def assignments_of(self, cars: list[DeviceView]) -> dict[str, Assignment]:
        return {car.device_id: self._assignments.for_staff(car.device_id) for car in cars}

    def preload_head(self, principal: User, event_id: str, track_id: str) -> RacerQueue:
        """Give the head's model to a free car (one that already holds it first, then an online one); record the car,
        or why there is none, on the entry."""
        queue = self._queue.queue(event_id, track_id)
        head = queue.head
        if head is None:
            return queue
        racing = self.racing_car(event_id, track_id)
        cars = [car for car in self.fleet_cars(event_id, track_id) if car.device_id != racing]
        if not cars:
            if head.car is None and head.preload_problem == NO_FREE_CAR:
                return queue  # already said: the queue's poll asks again every 2 s without writing each time
            return self._queue.set_car(event_id, track_id, head.entry_id, None, NO_FREE_CAR)
        held = self.assignments_of(cars)
        if head.car in held and _first_model(held[head.car]) == head.model_id:
            return queue if head.preload_problem is None else self._queue.set_car(
                event_id, track_id, head.entry_id, head.car)
        car = min(cars, key=lambda c: (head.model_id not in _model_ids(held[c.device_id]), not c.online,
                                       c.hostname, c.device_id))
        try:
            self._give(principal, head, held[car.device_id])
        except DremError as exc:  # the model was withdrawn meanwhile, the car deregistered: say so on the page
            return self._queue.set_car(event_id, track_id, head.entry_id, None,
                                       f"Could not give the model to {car.hostname}: {exc.message}")
        return self._queue.set_car(event_id, track_id, head.entry_id, car.device_id)

    def start_head(self, principal: User, event_id: str, track_id: str, entry_id: str, *,
                   raced_by_proxy: bool = False, override_max_runs: bool = False) -> dict[str, Any]:
        """Create the race for the queue's head on the car holding their model, take them off the queue, and give
        the next racer's model to a free car. The race and the queue change are one outcome: the race's id is
        recorded on the entry first, so a Start repeated after a crash (between the race and the queue change)
        finds that race and only finishes the queue change. If the race is refused, the queue keeps the racer."""
        queue = self._queue.queue(event_id, track_id)
        race_id = race_id_for_entry(event_id, track_id, entry_id)
        if all(e.entry_id != entry_id for e in queue.entries) and self._races.existing_race(event_id, race_id):
            # Start repeated after everything was done but its answer was lost (a crash or a dropped connection):
            # the race that Start made is the answer, not "who is next changed".
            return self._races.get_race(principal, event_id, race_id)
        head = _require_head(queue, entry_id)
        if head.starting_race_id and (started := self._races.existing_race(event_id, head.starting_race_id)):
            return self._finish_start(principal, event_id, track_id, entry_id, started.race.race_id)
        # The car the model went to may have been racing then (one car), or given other models since: check again.
        head = _require_head(self.preload_head(principal, event_id, track_id), entry_id)
        head = self._queue.mark_starting(event_id, track_id, entry_id, race_id)
        assert head.starting_race_id is not None
        race = self._races.create_race(principal, event_id, CreateRaceInput(
            track_id=track_id, racer_username=head.racer_username, car=head.car, raced_by_proxy=raced_by_proxy,
            override_max_runs=override_max_runs), race_id=head.starting_race_id)
        self._queue.remove(event_id, track_id, entry_id, missing_ok=True)
        self.preload_head(principal, event_id, track_id)
        return race

    def finish_interrupted_starts(self, principal: User, event_id: str, track_id: str) -> RacerQueue:
        """Before the queue is shown (its list polls this): take off a head whose race a crashed Start already created
        (the queue change never happened), so nobody sees a racer on deck who is racing; and give a head left without
        a car (every car was racing) the car a race ended elsewhere freed (race admin, the API, a timer), so "Ready
        race for X" names the car it will use."""
        queue = self._queue.queue(event_id, track_id)
        head = queue.head
        if head is None:
            return queue
        if head.starting_race_id and self._races.existing_race(event_id, head.starting_race_id):
            self._queue.remove(event_id, track_id, head.entry_id, missing_ok=True)
            return self.preload_head(principal, event_id, track_id)
        if head.car is None and head.preload_problem == NO_FREE_CAR and not self.race_live(event_id, track_id):
            return self.preload_head(principal, event_id, track_id)
        return queue

    def _finish_start(self, principal: User, event_id: str, track_id: str, entry_id: str,
                      race_id: str) -> dict[str, Any]:
        self._queue.remove(event_id, track_id, entry_id, missing_ok=True)
        self.preload_head(principal, event_id, track_id)
        return self._races.get_race(principal, event_id, race_id)

    def started_elsewhere(self, principal: User, event_id: str, track_id: str, racer_username: str) -> RacerQueue:
        """A race readied from the "Next race" form for a racer who was in line: they are off the queue, as if it
        had been started from there, and the next racer's model goes to a free car."""
        queue = self._queue.queue(event_id, track_id)
        wanted = racer_username.casefold()
        entry = next((e for e in queue.entries if e.racer_username.casefold() == wanted), None)
        if entry is not None:
            self._queue.remove(event_id, track_id, entry.entry_id, missing_ok=True)
        return self.preload_head(principal, event_id, track_id)

    def _give(self, principal: User, entry: QueueEntry, current: Assignment) -> None:
        others = [model_id for model_id in _model_ids(current) if model_id != entry.model_id]
        try:
            self._assignments.assign(principal, current.device_id, [entry.model_id, *others][:MAX_MODELS_PER_CAR])
        except DremError:
            if not others:
                raise
            # One of the car's other models was withdrawn since it was given: the racer's model alone, then.
            self._assignments.assign(principal, current.device_id, [entry.model_id])


_QUEUE_RACES = uuid.UUID("5c0e0d0a-7d1e-4b8e-9a55-0f1c2e3d4b5a")  # names the races Start makes from queue entries


def race_id_for_entry(event_id: str, track_id: str, entry_id: str) -> str:
    """The id of the race Start makes for a queue entry: always the same for that entry, so a repeated Start can find
    the race an earlier one made even after the entry left the queue. A new place in line is a new entry (a new id)."""
    return uuid.uuid5(_QUEUE_RACES, f"{event_id}/{track_id}/{entry_id}").hex


def _require_head(queue: RacerQueue, entry_id: str) -> QueueEntry:
    head = queue.head
    if head is None or head.entry_id != entry_id:
        raise Conflict("Who is next changed meanwhile (another screen edited the queue); check On deck and start "
                       "again.", field="entry_id")
    return head


def _model_ids(assignment: Assignment) -> list[str]:
    return [model.model_id for model in assignment.models]


def _first_model(assignment: Assignment) -> str | None:
    return assignment.models[0].model_id if assignment.models else None
