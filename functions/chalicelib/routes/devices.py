"""JSON API for cars and timers.

Staff: activation codes, the device list/status board, moving devices between fleets, deregistering (admins only),
queueing commands and reading their outcome. Devices (`Authorization: Device <id>.<secret>`): activate (public: the
code is the credential), heartbeat, rotate their own secret, fetch and acknowledge their own commands. Every `self`
route acts on the caller's own device id, taken from its verified credential.

`verify_device_credential` is what `chalicelib.core.principals.set_device_credential_verifier` must be given.
"""
from __future__ import annotations

from collections.abc import Mapping

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, CAR, OPERATOR, PUBLIC, TIMER, route
from chalicelib.auth.rate_limits import client_address, guarded_activation
from chalicelib.core.errors import InvalidInput
from chalicelib.core.principals import Device, Principal, User
from chalicelib.domain.activation import (
    ActivationCodeRequest,
    ActivationExchange,
    IssuedActivationCode,
    IssuedCredential,
)
from chalicelib.domain.devices import (
    CarVideoSettings,
    Command,
    CommandAck,
    CommandRequest,
    DeviceView,
    MoveToFleet,
    Telemetry,
)

bp = Blueprint(__name__)

DEVICE_STAFF = {ADMIN, OPERATOR}
DEVICES = {CAR, TIMER}


def verify_device_credential(credential: str) -> Device:
    return services.activation_service().verify(credential)


# --- staff ---
@route(bp, "/api/devices/activation-codes", methods=["POST"], allow=DEVICE_STAFF, body=ActivationCodeRequest,
       response=IssuedActivationCode, status_code=201)
def create_activation_code(principal: User, body: ActivationCodeRequest) -> Response:
    issued = services.activation_service().issue_code(principal, body)
    return Response(issued.model_dump(mode="json"), status_code=201, headers={"Cache-Control": "no-store"})


@route(bp, "/api/devices", methods=["GET"], allow=DEVICE_STAFF)
def list_devices(principal: User) -> dict:
    query: Mapping[str, str] = bp.current_request.query_params or {}
    devices = services.device_service().list_devices(online=_flag(query.get("online")), fleet_id=query.get("fleet_id"))
    return {"devices": [d.model_dump(mode="json") for d in devices]}


@route(bp, "/api/devices/{device_id}", methods=["GET"], allow=DEVICE_STAFF, response=DeviceView)
def get_device(principal: User, device_id: str) -> dict:
    return services.device_service().get_device(device_id).model_dump(mode="json")


@route(bp, "/api/devices/{device_id}/fleet", methods=["PUT"], allow=DEVICE_STAFF, body=MoveToFleet,
       response=DeviceView)
def move_device(principal: User, device_id: str, body: MoveToFleet) -> dict:
    return services.device_service().move_to_fleet(device_id, body.fleet_id).model_dump(mode="json")


@route(bp, "/api/devices/{device_id}/video", methods=["PUT"], allow=DEVICE_STAFF, body=CarVideoSettings,
       response=CarVideoSettings)
def set_car_video(principal: User, device_id: str, body: CarVideoSettings) -> dict:
    """The car's camera on the stream: frame rate, size, camera or model view (the car picks it up by itself)."""
    return services.device_service().set_video(device_id, body).model_dump(mode="json")


@route(bp, "/api/devices/{device_id}", methods=["DELETE"], allow={ADMIN})
def deregister_device(principal: User, device_id: str) -> Response:
    services.device_service().deregister(device_id)
    return Response(body="", status_code=204)


@route(bp, "/api/devices/{device_id}/commands", methods=["POST"], allow=DEVICE_STAFF, body=CommandRequest,
       response=Command, status_code=201)
def queue_command(principal: User, device_id: str, body: CommandRequest) -> Response:
    command = services.device_service().queue_command(principal, device_id, body)
    return Response(command.model_dump(mode="json"), status_code=201)


@route(bp, "/api/devices/{device_id}/commands", methods=["GET"], allow=DEVICE_STAFF)
def device_commands(principal: User, device_id: str) -> dict:
    return {"commands": [c.model_dump(mode="json") for c in services.device_service().device_commands(device_id)]}


# --- the device itself ---
# No CSRF check: a device has no session cookie to abuse; the one-time code in the body is its only credential.
@route(bp, "/api/devices/activate", methods=["POST"], allow=PUBLIC, csrf=False, body=ActivationExchange,
       response=IssuedCredential, status_code=201)
def activate_device(principal: Principal, body: ActivationExchange) -> Response:
    issued = guarded_activation(lambda: services.activation_service().activate(body),
                                client_address(bp.current_request))
    return Response(issued.model_dump(mode="json"), status_code=201, headers={"Cache-Control": "no-store"})


@route(bp, "/api/devices/self", methods=["GET"], allow=DEVICES, response=DeviceView)
def own_device(principal: Device) -> dict:
    return services.device_service().get_device(principal.device_id).model_dump(mode="json")


@route(bp, "/api/devices/self/rotate", methods=["POST"], allow=DEVICES, response=IssuedCredential)
def rotate_credential(principal: Device) -> Response:
    issued = services.activation_service().rotate(principal)
    return Response(issued.model_dump(mode="json"), headers={"Cache-Control": "no-store"})


@route(bp, "/api/devices/self/heartbeat", methods=["POST"], allow=DEVICES, body=Telemetry, response=DeviceView)
def heartbeat(principal: Device, body: Telemetry) -> dict:
    return services.device_service().heartbeat(principal, body).model_dump(mode="json")


@route(bp, "/api/devices/self/commands", methods=["GET"], allow=DEVICES)
def pending_commands(principal: Device) -> dict:
    return {"commands": [c.model_dump(mode="json") for c in services.device_service().pending_commands(principal)]}


@route(bp, "/api/devices/self/commands/{command_id}/ack", methods=["POST"], allow=DEVICES, body=CommandAck,
       response=Command)
def acknowledge_command(principal: Device, command_id: str, body: CommandAck) -> dict:
    return services.device_service().acknowledge(principal, command_id, body).model_dump(mode="json")


def _flag(value: str | None) -> bool | None:
    if value is None or value == "":
        return None
    if value.lower() in {"true", "1", "yes"}:
        return True
    if value.lower() in {"false", "0", "no"}:
        return False
    raise InvalidInput("online must be true or false.", field="online")
