"""JSON API for races: operators create and drive races, race admin edits/deletes/recomputes/exports, racers read
their own. Every handler parses its input and calls one service method; `race_service()` wires the adapters."""
from __future__ import annotations

import time

from chalice import Blueprint, Response
from pydantic import RootModel

from chalicelib.auth.access import ADMIN, COMMENTATOR, OPERATOR, SIGNED_IN, route
from chalicelib.auth.principals import Principal, User
from chalicelib.domain.leaderboards import LeaderboardPublisher
from chalicelib.domain.numbers import lap_number
from chalicelib.domain.profiles import ProfileService
from chalicelib.domain.races import CreateRaceInput, LapEdit, RaceService
from chalicelib.routes.users import user_directory
from chalicelib.settings import get_settings
from chalicelib.storage import clients
from chalicelib.storage.audit import DynamoAuditLog
from chalicelib.storage.events import DynamoEventStore
from chalicelib.storage.leaderboards import DynamoBoardStore
from chalicelib.storage.profiles import DynamoProfileStore
from chalicelib.storage.races import DynamoRaceStore
from drem_leaderboard.commands import RaceCommand
from drem_leaderboard.ranking import RacerProfile

bp = Blueprint(__name__)

RACE_STAFF = {ADMIN, OPERATOR}
RACE_READERS = {ADMIN, OPERATOR, COMMENTATOR}


def now_ms() -> int:
    return time.time_ns() // 1_000_000


class ProfilesForBoards:
    """Board names, flags and colours from racer profiles; a deleted racer comes back anonymised."""

    def __init__(self, profiles: ProfileService) -> None:
        self._profiles = profiles

    def racer_profile(self, sub: str, fallback_username: str) -> RacerProfile:
        public = self._profiles.public_by_sub(sub)
        if public is None:
            return RacerProfile(username=fallback_username)
        return RacerProfile(username=public.username, country_code=public.country_code,
                            highlight_colour=public.highlight_colour)


def race_store() -> DynamoRaceStore:
    return DynamoRaceStore(clients.dynamodb(), get_settings().table("races"))


def publisher() -> LeaderboardPublisher:
    return LeaderboardPublisher(DynamoBoardStore(clients.dynamodb(), get_settings().table("leaderboards")), now_ms)


def race_service() -> RaceService:
    settings, dynamodb = get_settings(), clients.dynamodb()
    profiles = ProfileService(DynamoProfileStore(dynamodb, settings.table("profiles")))
    return RaceService(race_store(), DynamoEventStore(dynamodb, settings.table("events")),
                       user_directory(settings), ProfilesForBoards(profiles), publisher(), now_ms,
                       audit=audit_log())


def audit_log() -> DynamoAuditLog:
    return DynamoAuditLog(clients.dynamodb(), get_settings().table("races"))


class RaceCommandBody(RootModel[RaceCommand]):
    """One race command, chosen by `kind` (e.g. {"kind": "capture_lap"}); the fields depend on the kind."""


@route(bp, "/api/events/{event_id}/races", methods=["POST"], allow=RACE_STAFF, body=CreateRaceInput, status_code=201)
def create_race(principal: User, event_id: str, body: CreateRaceInput) -> Response:
    race = race_service().create_race(principal, event_id, body)
    return Response(body=race, status_code=201)


@route(bp, "/api/events/{event_id}/races", methods=["GET"], allow=RACE_READERS)
def list_races(principal: User, event_id: str) -> dict:
    track = (bp.current_request.query_params or {}).get("track")
    return {"races": race_service().list_races(event_id, track)}


@route(bp, "/api/events/{event_id}/races/{race_id}", methods=["GET"], allow=SIGNED_IN)
def get_race(principal: Principal, event_id: str, race_id: str) -> dict:
    return race_service().get_race(principal, event_id, race_id)


@route(bp, "/api/me/races", methods=["GET"], allow=SIGNED_IN)
def my_races(principal: User) -> dict:
    return {"races": race_service().my_races(principal)}


@route(bp, "/api/events/{event_id}/races/{race_id}/commands", methods=["POST"], allow=RACE_STAFF,
       body=RaceCommandBody)
def race_command(principal: User, event_id: str, race_id: str, body: RaceCommandBody) -> dict:
    return race_service().apply_command(event_id, race_id, body.root, by=principal.username)


@route(bp, "/api/events/{event_id}/races/{race_id}/laps/{lap_id}", methods=["PUT"], allow=RACE_STAFF, body=LapEdit)
def edit_lap(principal: User, event_id: str, race_id: str, lap_id: str, body: LapEdit) -> dict:
    return race_service().edit_lap(event_id, race_id, lap_number(lap_id), body, by=principal.username)


@route(bp, "/api/events/{event_id}/races/{race_id}", methods=["DELETE"], allow=RACE_STAFF)
def delete_race(principal: User, event_id: str, race_id: str) -> Response:
    race_service().delete_race(event_id, race_id, by=principal.username)
    return Response(body="", status_code=204)


@route(bp, "/api/events/{event_id}/recompute", methods=["POST"], allow=RACE_STAFF)
def recompute(principal: User, event_id: str) -> dict:
    return race_service().recompute(event_id, by=principal.username)


@route(bp, "/api/events/{event_id}/export/{file_name}", methods=["GET"], allow=RACE_STAFF)
def export(principal: User, event_id: str, file_name: str) -> Response:
    csv_file = race_service().export(event_id, file_name)
    return Response(body=csv_file.text, status_code=200, headers={
        "Content-Type": "text/csv; charset=utf-8",
        "Content-Disposition": f'attachment; filename="{csv_file.filename}"'})
