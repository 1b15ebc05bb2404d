"""Timing-strip posts from devices (cars and timers): `POST /api/timing/strip-events`."""
from __future__ import annotations

from chalice import Blueprint

from chalicelib import services
from chalicelib.auth.access import CAR, TIMER, route
from chalicelib.core.principals import Device
from chalicelib.domain.timing import StripAnswer, StripPost

bp = Blueprint(__name__)


@route(bp, "/api/timing/strip-events", methods=["POST"], allow={CAR, TIMER}, body=StripPost, response=StripAnswer)
def strip_event(principal: Device, body: StripPost) -> dict:
    return services.timing_service().strip_event(principal, body).model_dump(mode="json")
