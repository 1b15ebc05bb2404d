"""JSON API for fleets (admins and operators)."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, route
from chalicelib.core.principals import User
from chalicelib.domain.devices import CarVideoSettings
from chalicelib.domain.fleets import Fleet, FleetInput

bp = Blueprint(__name__)

FLEET_STAFF = {ADMIN, OPERATOR}


@route(bp, "/api/fleets", methods=["GET"], allow=FLEET_STAFF)
def list_fleets(principal: User) -> dict:
    return {"fleets": [f.model_dump(mode="json") for f in services.fleet_service().list_fleets()]}


@route(bp, "/api/fleets", methods=["POST"], allow=FLEET_STAFF, body=FleetInput, response=Fleet, status_code=201)
def create_fleet(principal: User, body: FleetInput) -> Response:
    return Response(services.fleet_service().create_fleet(principal, body).model_dump(mode="json"), status_code=201)


@route(bp, "/api/fleets/{fleet_id}", methods=["GET"], allow=FLEET_STAFF, response=Fleet)
def get_fleet(principal: User, fleet_id: str) -> dict:
    return services.fleet_service().get_fleet(fleet_id).model_dump(mode="json")


@route(bp, "/api/fleets/{fleet_id}", methods=["PUT"], allow=FLEET_STAFF, body=FleetInput, response=Fleet)
def update_fleet(principal: User, fleet_id: str, body: FleetInput) -> dict:
    return services.fleet_service().update_fleet(principal, fleet_id, body).model_dump(mode="json")


@route(bp, "/api/fleets/{fleet_id}/video", methods=["PUT"], allow=FLEET_STAFF, body=CarVideoSettings)
def set_fleet_video(principal: User, fleet_id: str, body: CarVideoSettings) -> dict:
    """Every car of the fleet sends its camera at these settings (docs/cars.md); the cars it set, by device id."""
    return {"video": body.model_dump(mode="json"), "cars": services.device_service().set_fleet_video(fleet_id, body)}


@route(bp, "/api/fleets/{fleet_id}", methods=["DELETE"], allow=FLEET_STAFF)
def delete_fleet(principal: User, fleet_id: str) -> Response:
    services.fleet_service().delete_fleet(principal, fleet_id)
    return Response(body="", status_code=204)
