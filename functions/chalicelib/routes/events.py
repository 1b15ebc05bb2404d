"""JSON API for events: staff read them, admins and operators create, replace and delete them."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, COMMENTATOR, OPERATOR, REGISTRATION, route
from chalicelib.core.principals import User
from chalicelib.domain.events import Event, EventInput

bp = Blueprint(__name__)

EVENT_READERS = {ADMIN, OPERATOR, COMMENTATOR, REGISTRATION}
EVENT_EDITORS = {ADMIN, OPERATOR}


@route(bp, "/api/events", methods=["GET"], allow=EVENT_READERS)
def list_events(principal: User) -> dict:
    return {"events": [e.model_dump(mode="json") for e in services.event_service().list_events()]}


@route(bp, "/api/events", methods=["POST"], allow=EVENT_EDITORS, body=EventInput, response=Event, status_code=201)
def create_event(principal: User, body: EventInput) -> Response:
    return Response(services.event_service().create_event(principal, body).model_dump(mode="json"), status_code=201)


@route(bp, "/api/events/{event_id}", methods=["GET"], allow=EVENT_READERS, response=Event)
def get_event(principal: User, event_id: str) -> dict:
    return services.event_service().get_event(event_id).model_dump(mode="json")


@route(bp, "/api/events/{event_id}", methods=["PUT"], allow=EVENT_EDITORS, body=EventInput, response=Event)
def replace_event(principal: User, event_id: str, body: EventInput) -> dict:
    return services.event_service().update_event(principal, event_id, body).model_dump(mode="json")


@route(bp, "/api/events/{event_id}", methods=["DELETE"], allow=EVENT_EDITORS)
def delete_event(principal: User, event_id: str) -> Response:
    services.event_service().delete_event(principal, event_id)
    return Response(body="", status_code=204)
