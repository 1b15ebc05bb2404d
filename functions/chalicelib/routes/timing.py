"""Timing-strip posts from devices (cars and timers): `POST /api/timing/strip-events`."""
from __future__ import annotations

from chalice import Blueprint

from chalicelib.auth.access import CAR, TIMER, route
from chalicelib.auth.principals import Device
from chalicelib.domain.timing import StripAnswer, StripPost, TimingService
from chalicelib.routes.races import now_ms, race_service, race_store
from chalicelib.settings import get_settings
from chalicelib.storage import clients
from chalicelib.storage.devices import DynamoDeviceStore

bp = Blueprint(__name__)


def timing_service() -> TimingService:
    devices = DynamoDeviceStore(clients.dynamodb(), get_settings().table("fleet"))
    return TimingService(race_service(), race_store(), devices, now_ms)


@route(bp, "/api/timing/strip-events", methods=["POST"], allow={CAR, TIMER}, body=StripPost, response=StripAnswer)
def strip_event(principal: Device, body: StripPost) -> dict:
    return timing_service().strip_event(principal, body).model_dump(mode="json")
