"""Operator console: fleets, the cars/timers page (status, per-car actions → device commands, model assignment) and
device activation (a one-time code plus the command to run on the car or timer). Same services as the JSON API."""
from __future__ import annotations

from urllib.parse import quote

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, route
from chalicelib.core.errors import NotFound
from chalicelib.core.principals import User
from chalicelib.domain.activation import ActivationCodeRequest
from chalicelib.domain.devices import CarVideoSettings, CommandRequest
from chalicelib.domain.fleets import FleetInput
from chalicelib.routes.console.forms import (
    SHOWN_ON_FORM,
    checkbox,
    error_status,
    field_errors,
    optional,
    redirect,
    submitted,
)
from chalicelib.routes.console.notices import done_notice
from chalicelib.settings import get_settings
from chalicelib.views.camera_choice import VIDEO_RATES, VIDEO_SIZES
from chalicelib.views.car_console import COMMAND_LABELS, CarsOverview, cars_overview
from chalicelib.views.car_video import preview_video_url
from chalicelib.views.fleet_console import fleet_lines, fleet_video_notice
from drem_web import render

bp = Blueprint(__name__)

DEVICE_STAFF = {ADMIN, OPERATOR}


@route(bp, "/console/fleets", allow=DEVICE_STAFF)
def fleets_page(principal: User) -> Response:
    return _fleets_page({}, {})


@route(bp, "/console/fleets", methods=["POST"], allow=DEVICE_STAFF)
def create_fleet(principal: User) -> Response:
    values = submitted(bp.current_request, "name")
    try:
        services.fleet_service().create_fleet(principal, FleetInput.model_validate(values))
    except SHOWN_ON_FORM as exc:
        return _fleets_page(field_errors(exc), values, error_status(exc))
    return redirect("/console/fleets", done="fleet-created")


@route(bp, "/console/fleets/{fleet_id}/video", methods=["POST"], allow=DEVICE_STAFF)
def fleet_video(principal: User, fleet_id: str) -> Response:
    """Every car of the fleet gets the same camera settings; the page says how many cars got them. Bad input is
    refused before any car is changed (a size that does not parse is the size's fault)."""
    values = submitted(bp.current_request, "fps", "size", "view")
    try:
        video = CarVideoSettings.model_validate(values)
        cars = services.device_service().set_fleet_video(fleet_id, video)
    except SHOWN_ON_FORM as exc:
        errors = {f"{fleet_id}-{name}": message for name, message in field_errors(exc, "size").items()}
        return _fleets_page(errors, {}, error_status(exc))
    name = services.fleet_service().get_fleet(fleet_id).name
    return _fleets_page({}, {}, notice=fleet_video_notice(name, len(cars), video))


@route(bp, "/console/cars", allow=DEVICE_STAFF)
def cars_page(principal: User) -> Response:
    request = bp.current_request
    return _cars_page(principal, {}, notice=_sent_notice(request.query_params or {}) or done_notice(request))


@route(bp, "/console/cars/live", allow=DEVICE_STAFF)
def cars_live(principal: User) -> Response:
    """Every car's status cell (status, battery, faults, loaded model, last command) as out-of-band swaps: the page
    polls this, so the operator sees an emergency stop confirmed without reloading"""
    return render.fragment("console/cars_live", cars=_overview(principal).cars, headers={"Cache-Control": "no-store"})


@route(bp, "/console/cars/activate", allow=DEVICE_STAFF)
def activation_page(principal: User) -> Response:
    return _activation_page({}, {"device_kind": "car", "ttl_minutes": "60"}, None)


@route(bp, "/console/cars/activate", methods=["POST"], allow=DEVICE_STAFF)
def create_activation_code(principal: User) -> Response:
    values = submitted(bp.current_request, "device_kind", "hostname", "fleet_id", "ttl_minutes")
    try:
        issued = services.activation_service().issue_code(principal, ActivationCodeRequest.model_validate(values))
    except SHOWN_ON_FORM as exc:
        return _activation_page(field_errors(exc), values, None, error_status(exc))
    return _activation_page({}, values, issued)


@route(bp, "/console/cars/{device_id}/commands", methods=["POST"], allow=DEVICE_STAFF)
def car_command(principal: User, device_id: str) -> Response:
    values = submitted(bp.current_request, "type", "colour", "with_system_logs")
    command = {"type": values.get("type", ""), "colour": optional(values.get("colour")),
               **({"with_system_logs": True} if checkbox(values, "with_system_logs") else {})}
    return _car_action(principal, device_id, lambda: services.device_service().queue_command(
        principal, device_id, CommandRequest.model_validate(command)), sent=values.get("type", ""))


@route(bp, "/console/cars/{device_id}/fleet", methods=["POST"], allow=DEVICE_STAFF)
def move_car(principal: User, device_id: str) -> Response:
    fleet_id = optional(submitted(bp.current_request, "fleet_id").get("fleet_id"))
    return _car_action(principal, device_id, lambda: services.device_service().move_to_fleet(device_id, fleet_id),
                       done="car-moved")


@route(bp, "/console/cars/{device_id}/models", methods=["POST"], allow=DEVICE_STAFF)
def assign_model(principal: User, device_id: str) -> Response:
    values = submitted(bp.current_request, "clear", "model_id")
    service = services.assignment_service()

    def assign() -> object:
        current = [m.model_id for m in service.for_staff(device_id).models]
        wanted = [] if values.get("clear") == "1" else current + [m for m in [optional(values.get("model_id"))]
                                                                  if m and m not in current]
        return service.assign(principal, device_id, wanted)

    return _car_action(principal, device_id, assign, done="car-models")


@route(bp, "/console/cars/{device_id}/video", methods=["POST"], allow=DEVICE_STAFF)
def car_video(principal: User, device_id: str) -> Response:
    values = submitted(bp.current_request, "fps", "size", "view")
    return _car_action(principal, device_id, lambda: services.device_service().set_video(
        device_id, CarVideoSettings.model_validate(values)), done="car-video")


@route(bp, "/console/cars/{device_id}/deregister", methods=["POST"], allow={ADMIN})
def deregister_car(principal: User, device_id: str) -> Response:
    return _car_action(principal, device_id, lambda: services.device_service().deregister(device_id),
                       done="car-deregistered")


def _car_action(principal: User, device_id: str, action, sent: str = "",  # noqa: ANN001 - a thunk
                done: str = "") -> Response:
    """Run one car's action; a refusal is shown in that car's row (errors keyed `{device_id}-{field}`)."""
    try:
        action()
    except SHOWN_ON_FORM as exc:
        errors = {f"{device_id}-{name}": message for name, message in field_errors(exc).items()}
        return _cars_page(principal, errors, error_status(exc))
    query = f"?sent={quote(sent)}&device={quote(device_id)}" if sent else ""
    return redirect(f"/console/cars{query}#car-{device_id}", done=done)


def _fleets_page(errors: dict[str, str], values: dict[str, str], status: int = 200, notice: str = "") -> Response:
    """The page after a post answers it directly (a fleet's camera: the count of cars is the one just set)."""
    fleets = fleet_lines(services.fleet_service().list_fleets(), services.device_service().list_devices())
    return render.page("console/fleets", status=status, fleets=fleets, errors=errors, values=values,
                       flash=notice or (done_notice(bp.current_request) if status == 200 else ""),
                       video_sizes=VIDEO_SIZES, video_rates=VIDEO_RATES)


def _sent_notice(query: dict[str, str]) -> str:
    """"Emergency stop sent to car-1 …" after a command, built from known values only (never echoes the query)."""
    label = COMMAND_LABELS.get(query.get("sent", ""))
    device_id = query.get("device", "")
    if not label or not device_id:
        return ""
    try:
        hostname = services.device_service().get_device(device_id).hostname
    except NotFound:
        return ""
    return f"{label} sent to {hostname}. Its status below shows when the car has done it."


def _cars_page(principal: User, errors: dict[str, str], status: int = 200, notice: str = "") -> Response:
    return render.page("console/cars", status=status, overview=_overview(principal), errors=errors,
                       is_admin=ADMIN in principal.roles, notice=notice, camera_url=preview_video_url,
                       video_sizes=VIDEO_SIZES, video_rates=VIDEO_RATES)


def _overview(principal: User) -> CarsOverview:
    """The page and its poll name racers alike (views/car_console.py)."""
    return cars_overview(principal, services.device_service(), services.fleet_service(), services.assignment_service(),
                         services.model_service(), services.profile_service().public_by_subs, services.now_ms())


def _activation_page(errors: dict[str, str], values: dict[str, str], issued: object, status: int = 200) -> Response:
    return render.page("console/activation", status=status, errors=errors, values=values, issued=issued,
                       fleets=services.fleet_service().list_fleets(), api_url=get_settings().public_url)
