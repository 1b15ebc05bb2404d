"""Operator console: the racer queue ("on deck") beside the timekeeper screen. Staff add a racer with their model,
move them up or down, take them off; the timekeeper starts the head's race in one click (domain/on_deck.py).

The panel's list polls itself (every 2 s) so the pre-load state follows the car; the add form sits outside the
polled list so nothing typed is swapped away."""
from __future__ import annotations

from collections.abc import Callable

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, route
from chalicelib.core.principals import User
from chalicelib.domain.racer_queue import AddToQueue, MoveInQueue, QueueEntryRef
from chalicelib.routes.console.forms import SHOWN_ON_FORM, error_status, field_errors, submitted
from chalicelib.views.on_deck_panel import QueuePanel, queue_panel
from drem_web import render

bp = Blueprint(__name__)

QUEUE_STAFF = {ADMIN, OPERATOR}  # the timekeepers: who runs the track
BASE = "/console/timekeeper/{event_id}/{track_id}/queue"
# Tells the timekeeper's race panel (templates/partials/console/tk_state.html) to fetch the race just started.
RACE_STARTED = {"HX-Trigger": "tk-race-started"}


@route(bp, BASE, allow=QUEUE_STAFF)
def queue_list(principal: User, event_id: str, track_id: str) -> Response:
    try:  # a head whose race a crashed Start created leaves the queue here, so the list is true when it polls
        services.on_deck().finish_interrupted_starts(principal, event_id, track_id)
    except SHOWN_ON_FORM:
        pass  # the list below shows the queue as stored; the next poll tries again
    return _list(event_id, track_id)


@route(bp, BASE, methods=["POST"], allow=QUEUE_STAFF)
def add_to_queue(principal: User, event_id: str, track_id: str) -> Response:
    values = submitted(bp.current_request, "queue_racer", "queue_model", "queue_confirmed")
    data = {"racer_username": values.get("queue_racer", "").strip(), "model": values.get("queue_model", ""),
            "confirmed": values.get("queue_confirmed") == "yes"}
    try:
        services.on_deck().add(principal, event_id, track_id, AddToQueue.model_validate(data))
    except SHOWN_ON_FORM as exc:
        errors = field_errors(exc, rename=_form_name, missing_object_field="queue_racer")  # nobody by that name
        return _panel(event_id, track_id, errors, values, error_status(exc))
    return _panel(event_id, track_id)


@route(bp, BASE + "/move", methods=["POST"], allow=QUEUE_STAFF)
def move_in_queue(principal: User, event_id: str, track_id: str) -> Response:
    return _changed(event_id, track_id, lambda: services.on_deck().move(
        principal, event_id, track_id, MoveInQueue.model_validate(_button())))


@route(bp, BASE + "/remove", methods=["POST"], allow=QUEUE_STAFF)
def remove_from_queue(principal: User, event_id: str, track_id: str) -> Response:
    return _changed(event_id, track_id, lambda: services.on_deck().remove(
        principal, event_id, track_id, QueueEntryRef.model_validate(_button()).entry_id))


@route(bp, BASE + "/start", methods=["POST"], allow=QUEUE_STAFF)
def start_head(principal: User, event_id: str, track_id: str) -> Response:
    return _changed(event_id, track_id, lambda: services.on_deck().start_head(
        principal, event_id, track_id, QueueEntryRef.model_validate(_button()).entry_id), headers=RACE_STARTED)


def _changed(event_id: str, track_id: str, change: Callable[[], object],
             headers: dict[str, str] | None = None) -> Response:
    """Apply one change from a queue row's button; the queue again, with the message beside the row if refused."""
    try:
        change()
    except SHOWN_ON_FORM as exc:
        return _list(event_id, track_id, field_errors(exc, rename=_form_name, missing_object_field="form"),
                     error_status(exc))
    return _list(event_id, track_id, headers=headers)


def _button() -> dict[str, str]:
    return submitted(bp.current_request, "entry_id", "direction")  # a row button's hx-vals


_INPUTS = {"racer_username": "queue_racer", "username": "queue_racer", "model": "queue_model",
           "confirm": "queue_confirm"}


def _form_name(name: str) -> str:
    # The queue's inputs have their own names (the race form beside them has a racer_username too); errors from the
    # race a start creates name the race's fields, and on the queue they belong to the whole panel.
    return _INPUTS.get(name, "form")


def _list(event_id: str, track_id: str, errors: dict[str, str] | None = None, status: int = 200,
          headers: dict[str, str] | None = None) -> Response:
    return render.fragment("console/tk_queue_list", status=status, headers=headers,
                           queue=_queue(event_id, track_id), queue_errors=errors or {})


def _panel(event_id: str, track_id: str, errors: dict[str, str] | None = None, values: dict[str, str] | None = None,
           status: int = 200) -> Response:
    return render.fragment("console/tk_queue", status=status, queue=_queue(event_id, track_id),
                           queue_errors=errors or {}, queue_values=values or {})


def _queue(event_id: str, track_id: str) -> QueuePanel:
    return queue_panel(services.on_deck(), services.profile_service().public_by_subs, event_id, track_id)
