"""JSON API for giving models to cars, the car's own view of its assignment, and the staff status table.

Per-object rule: a car reads and reports only its own assignment (`/api/devices/self/...` takes the device id from
the verified device credential, never from the URL or body).
"""
from __future__ import annotations

from chalice import Blueprint

from chalicelib import services
from chalicelib.auth.access import ADMIN, CAR, OPERATOR, STAFF, route
from chalicelib.core.principals import Device, User
from chalicelib.domain.assignments import AssignInput, AssignmentQuery, StatusReport

bp = Blueprint(__name__)


@route(bp, "/api/cars/{device_id}/models", methods=["PUT"], allow={ADMIN, OPERATOR}, body=AssignInput)
def assign_models(principal: User, device_id: str, body: AssignInput) -> dict:
    return {"assignment": services.assignment_service().assign(principal, device_id, body.model_ids).public()}


@route(bp, "/api/cars/{device_id}/models", allow=STAFF)
def car_models(principal: User, device_id: str) -> dict:
    return {"assignment": services.assignment_service().for_staff(device_id).public()}


@route(bp, "/api/devices/self/assignment", allow={CAR}, query=AssignmentQuery)
def own_assignment(principal: Device, query: AssignmentQuery) -> dict:
    """The car's models; `wait_for_version=N&wait_s=20` answers as soon as staff change them (a long poll)"""
    return services.assignment_service().for_car(principal, query)


@route(bp, "/api/devices/self/assignment/status", methods=["POST"], allow={CAR}, body=StatusReport)
def report_model_status(principal: Device, body: StatusReport) -> dict:
    progress = services.assignment_service().report(principal, body)
    return {"progress": progress.model_dump(mode="json")}


@route(bp, "/api/events/{event_id}/model-status", allow=STAFF)
def event_model_status(principal: User, event_id: str) -> dict:
    rows = services.assignment_service().event_status(event_id)
    return {"event_id": event_id, "rows": [row.model_dump(mode="json") for row in rows]}
