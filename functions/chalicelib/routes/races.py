"""JSON API for races: operators create and drive races, race admin edits/deletes/recomputes/exports, racers read
their own. Every handler parses its input and calls one service method; `race_service()` wires the adapters."""
from __future__ import annotations

from collections.abc import Mapping

from chalice import Blueprint, Response
from pydantic import RootModel

from chalicelib import services
from chalicelib.auth.access import ADMIN, COMMENTATOR, OPERATOR, SIGNED_IN, route
from chalicelib.core.principals import Principal, User
from chalicelib.domain.numbers import lap_number
from chalicelib.domain.races import CreateRaceInput, LapEdit
from drem_leaderboard.commands import RaceCommand

bp = Blueprint(__name__)

RACE_STAFF = {ADMIN, OPERATOR}
RACE_READERS = {ADMIN, OPERATOR, COMMENTATOR}


class RaceCommandBody(RootModel[RaceCommand]):
    """One race command, chosen by `kind` (e.g. {"kind": "capture_lap"}); the fields depend on the kind."""


@route(bp, "/api/events/{event_id}/races", methods=["POST"], allow=RACE_STAFF, body=CreateRaceInput, status_code=201)
def create_race(principal: User, event_id: str, body: CreateRaceInput) -> Response:
    race = services.race_service().create_race(principal, event_id, body)
    return Response(body=race, status_code=201)


@route(bp, "/api/events/{event_id}/races", methods=["GET"], allow=RACE_READERS)
def list_races(principal: User, event_id: str) -> dict:
    query: Mapping[str, str] = bp.current_request.query_params or {}
    track = query.get("track")
    return {"races": services.race_service().list_races(event_id, track)}


@route(bp, "/api/events/{event_id}/races/{race_id}", methods=["GET"], allow=SIGNED_IN)
def get_race(principal: Principal, event_id: str, race_id: str) -> dict:
    return services.race_service().get_race(principal, event_id, race_id)


@route(bp, "/api/me/races", methods=["GET"], allow=SIGNED_IN)
def my_races(principal: User) -> dict:
    return {"races": services.race_service().my_races(principal)}


@route(bp, "/api/events/{event_id}/races/{race_id}/commands", methods=["POST"], allow=RACE_STAFF,
       body=RaceCommandBody)
def race_command(principal: User, event_id: str, race_id: str, body: RaceCommandBody) -> dict:
    return services.race_service().apply_command(event_id, race_id, body.root, by=principal.username)


@route(bp, "/api/events/{event_id}/races/{race_id}/laps/{lap_id}", methods=["PUT"], allow=RACE_STAFF, body=LapEdit)
def edit_lap(principal: User, event_id: str, race_id: str, lap_id: str, body: LapEdit) -> dict:
    return services.race_service().edit_lap(event_id, race_id, lap_number(lap_id), body, by=principal.username)


@route(bp, "/api/events/{event_id}/races/{race_id}", methods=["DELETE"], allow=RACE_STAFF)
def delete_race(principal: User, event_id: str, race_id: str) -> Response:
    services.race_service().delete_race(event_id, race_id, by=principal.username)
    return Response(body="", status_code=204)


@route(bp, "/api/events/{event_id}/recompute", methods=["POST"], allow=RACE_STAFF)
def recompute(principal: User, event_id: str) -> dict:
    return services.race_service().recompute(event_id, by=principal.username)


@route(bp, "/api/events/{event_id}/export/{file_name}", methods=["GET"], allow=RACE_STAFF)
def export(principal: User, event_id: str, file_name: str) -> Response:
    csv_file = services.race_service().export(event_id, file_name)
    return Response(body=csv_file.text, status_code=200, headers={
        "Content-Type": "text/csv; charset=utf-8",
        "Content-Disposition": f'attachment; filename="{csv_file.filename}"'})
