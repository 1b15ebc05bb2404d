"""What the timekeeper's queue panel shows: the racers in line (the first three "on deck"), each with their model and,
for the racer whose model went to a car, how far that car got: assigned, loading, loaded (the car's heartbeat names
the model it has loaded) or failed. Racers are named by display name, told apart among the racers in line."""
from __future__ import annotations

from pydantic import BaseModel

from chalicelib.domain.assignments import Assignment, CarModelStatus
from chalicelib.domain.devices import DeviceView
from chalicelib.domain.on_deck import OnDeck
from chalicelib.domain.racer_queue import QueueEntry
from chalicelib.views.racer_names import ProfilesBySub, shown_racer_names

ON_DECK = 3


class QueueRow(BaseModel):
    entry_id: str
    position: int
    racer: str
    model_name: str
    on_deck: bool
    is_head: bool
    car_label: str | None
    preload: str  # "", "assigned", "loading", "loaded", "failed", "no car"
    preload_text: str


class QueuePanel(BaseModel):
    event_id: str
    track_id: str
    race_live: bool
    racing_car: str | None
    rows: list[QueueRow]

    @property
    def on_deck(self) -> list[QueueRow]:
        return [row for row in self.rows if row.on_deck]

    @property
    def later(self) -> list[QueueRow]:
        return [row for row in self.rows if not row.on_deck]


def queue_panel(on_deck: OnDeck, profiles: ProfilesBySub, event_id: str, track_id: str) -> QueuePanel:
    queue = on_deck.queue(event_id, track_id)
    racers = shown_racer_names([(e.racer_sub, e.racer_username) for e in queue.entries], profiles)
    cars = {car.device_id: car for car in on_deck.fleet_cars(event_id, track_id)} if queue.entries else {}
    with_car = [cars[e.car] for e in queue.entries[:1] if e.car in cars]
    held = on_deck.assignments_of(with_car)
    racing = on_deck.racing_car(event_id, track_id)
    rows = [_row(index, entry, racers[entry.racer_sub], cars.get(entry.car or ""), held.get(entry.car or ""), racing)
            for index, entry in enumerate(queue.entries)]
    return QueuePanel(event_id=event_id, track_id=track_id, race_live=on_deck.race_live(event_id, track_id),
                      racing_car=racing, rows=rows)


def _row(index: int, entry: QueueEntry, racer: str, car: DeviceView | None, assignment: Assignment | None,
         racing: str | None) -> QueueRow:
    # Only the head's model is kept on a car; a racer moved down keeps their old car on record until they are next.
    preload, text = preload_state(entry, car, assignment, racing) if index == 0 else ("", "")
    return QueueRow(entry_id=entry.entry_id, position=index + 1, racer=racer,
                    model_name=entry.model_name, on_deck=index < ON_DECK, is_head=index == 0,
                    car_label=car.hostname if car else None, preload=preload, preload_text=text)


def preload_state(entry: QueueEntry, car: DeviceView | None, assignment: Assignment | None,
                  racing: str | None) -> tuple[str, str]:
    """(state, what the page says) of the entry's model on its car."""
    if entry.preload_problem:
        return "no car", entry.preload_problem
    if entry.car is None or car is None:
        return "", ""
    model = next((m for m in (assignment.models if assignment else []) if m.model_id == entry.model_id), None)
    if assignment is None or model is None:
        return "no car", f"{car.hostname} no longer holds this model: it is given to a car again when the queue moves."
    if car.device_id == racing:
        return "assigned", f"{car.hostname} is in the current race"
    loaded = car.telemetry.model if car.telemetry else None
    if loaded is not None and model.archive_md5 and loaded.md5 == model.archive_md5:
        return "loaded", f"loaded on {car.hostname}" + ("" if car.online else " (car offline)")
    progress = assignment.progress_of(entry.model_id)
    status = progress.status if progress else CarModelStatus.ASSIGNED
    if status is CarModelStatus.FAILED:
        return "failed", f"{car.hostname} could not load it: {progress.reason if progress else ''}"
    if status is CarModelStatus.ASSIGNED:
        return "assigned", f"assigned to {car.hostname}" + ("" if car.online else " (car offline)")
    return "loading", f"loading on {car.hostname} ({status.value})"
