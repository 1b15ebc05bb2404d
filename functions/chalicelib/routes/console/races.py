"""Operator console: race admin. The races of an event (filter by track), lap edits (time, resets, validity), delete
with confirmation, and the CSV downloads of the JSON API. Same `RaceService` as the JSON API."""
from __future__ import annotations

from collections.abc import Mapping
from datetime import UTC, datetime
from decimal import Decimal, InvalidOperation
from typing import Any

from chalice import Blueprint, Response
from pydantic import BaseModel, ConfigDict, Field

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, route
from chalicelib.core.errors import InvalidInput
from chalicelib.core.principals import User
from chalicelib.domain import audit
from chalicelib.domain.numbers import lap_number, whole_number
from chalicelib.domain.profiles import PublicProfile
from chalicelib.domain.races import LapEdit
from chalicelib.routes.console.forms import SHOWN_ON_FORM, checkbox, error_status, field_errors, redirect, submitted
from chalicelib.routes.console.notices import done_notice
from chalicelib.views.timekeeper_desk import clock_text
from drem_web import render

bp = Blueprint(__name__)

RACE_ADMINS = {ADMIN, OPERATOR}


class RaceFilter(BaseModel):
    model_config = ConfigDict(extra="ignore")
    event_id: str = Field(default="", max_length=64)
    track: str = Field(default="", max_length=32)


@route(bp, "/console/races", allow=RACE_ADMINS, query=RaceFilter)
def races_page(principal: User, query: RaceFilter) -> Response:
    events = services.event_service().list_events()
    event = next((e for e in events if e.event_id == query.event_id), events[0] if events else None)
    races = services.race_service().list_races(event.event_id, query.track or None) if event else []
    shown = services.profile_service().public_by_subs(list({r["racer_sub"] for r in races}))
    return render.page("console/races", events=events, event=event, track=query.track,
                       races=[_race_row(r, shown) for r in reversed(races)],
                       audit=_audit_rows(event.event_id) if event else [], flash=done_notice(bp.current_request))


@route(bp, "/console/races/{event_id}/{race_id}", allow=RACE_ADMINS)
def race_edit_page(principal: User, event_id: str, race_id: str) -> Response:
    return _edit_page(principal, event_id, race_id, {})


@route(bp, "/console/races/{event_id}/{race_id}/laps/{lap_id}", methods=["POST"], allow=RACE_ADMINS)
def edit_lap(principal: User, event_id: str, race_id: str, lap_id: str) -> Response:
    values = submitted(bp.current_request, "time_s", "resets", "is_valid")
    try:
        services.race_service().edit_lap(event_id, race_id, _lap_number(lap_id), _lap_edit(values),
                                         by=principal.username)
    except SHOWN_ON_FORM as exc:
        # One form per lap row: the messages are keyed `lap-{lap_id}-{field}` to sit in that row.
        errors = field_errors(exc, rename=lambda name: "time_s" if name == "time_ms" else name)
        return _edit_page(principal, event_id, race_id, {f"lap-{lap_id}-{name}": message
                                                         for name, message in errors.items()}, error_status(exc))
    return redirect(f"/console/races/{event_id}/{race_id}", done="lap-saved")


@route(bp, "/console/races/{event_id}/{race_id}/delete", allow=RACE_ADMINS)
def confirm_delete_page(principal: User, event_id: str, race_id: str) -> Response:
    race = services.race_service().get_race(principal, event_id, race_id)
    return render.page("console/race_delete", race=race, errors={})


@route(bp, "/console/races/{event_id}/{race_id}/delete", methods=["POST"], allow=RACE_ADMINS)
def delete_race(principal: User, event_id: str, race_id: str) -> Response:
    try:
        services.race_service().delete_race(event_id, race_id, by=principal.username)
    except SHOWN_ON_FORM as exc:
        # The confirmation has no inputs: every refusal goes at its top.
        return render.page("console/race_delete", status=error_status(exc),
                           race=services.race_service().get_race(principal, event_id, race_id),
                           errors=field_errors(exc, rename=lambda _name: "form"))
    return redirect(f"/console/races?event_id={event_id}", done="race-deleted")


def _edit_page(principal: User, event_id: str, race_id: str, errors: dict[str, str], status: int = 200) -> Response:
    race = services.race_service().get_race(principal, event_id, race_id)
    laps = [{**lap, "seconds": f"{Decimal(lap['time_ms']) / 1000:.3f}", "time": clock_text(lap["time_ms"])}
            for lap in race["laps"]]
    track = services.race_service().event(event_id).track_name(race["track_id"])
    profile = services.profile_service().public_by_sub(race["racer"]["sub"])
    racer = profile.display_name if profile and profile.display_name else race["racer"]["username"]
    return render.page("console/race_edit", status=status, race=race, laps=laps, errors=errors, track=track,
                       racer=racer,
                       created=_when(race["created_at_ms"]), audit=_audit_rows(event_id, race_id),
                       flash=done_notice(bp.current_request) if status == 200 else "")


def _audit_rows(event_id: str, race_id: str | None = None) -> list[dict[str, str]]:
    entries = audit.newest_first(services.audit_log().for_event(event_id), race_id)
    names = services.profile_service().shown_names([e.racer for e in entries if e.racer])  # as the boards name them
    return [{"action": e.action, "when": _when(e.at_ms), "by": e.by, "what": audit.ACTION_LABELS[e.action],
             "racer": names.get(e.racer or "", e.racer or ""), "lap": "" if e.lap_id is None else str(e.lap_id + 1),
             "before": audit.describe(e.before), "after": audit.describe(e.after)} for e in entries]


def _lap_number(lap_id: str) -> int:
    return lap_number(lap_id)


MAX_LAP_SECONDS = 3600  # LapEdit's own bound (time_ms <= 3,600,000)
MAX_RESETS = 1000


def _lap_edit(values: dict[str, str]) -> LapEdit:
    try:
        seconds = Decimal(values.get("time_s", "").strip())
    except InvalidOperation:
        raise InvalidInput("Write the lap time in seconds, e.g. 12.345.", field="time_s") from None
    # Bounded before int(): Decimal("1e999999999") is finite, and turning it into an int would take gigabytes.
    if not seconds.is_finite() or not 0 <= seconds <= MAX_LAP_SECONDS:
        raise InvalidInput(f"Write the lap time in seconds, e.g. 12.345 (at most {MAX_LAP_SECONDS}).", field="time_s")
    resets = whole_number(values.get("resets", ""), field="resets", message="Resets is a whole number (0 or more).",
                          maximum=MAX_RESETS)
    return LapEdit(time_ms=int(seconds * 1000), resets=resets, is_valid=checkbox(values, "is_valid"))


def _race_row(race: dict[str, Any], shown: Mapping[str, PublicProfile]) -> dict[str, Any]:
    profile = shown.get(race["racer_sub"])
    return {**race, "created": _when(race["created_at_ms"]),
            "racer": profile.display_name if profile and profile.display_name else race["username"],
            "fastest": clock_text(race["fastest_lap_ms"]) if race["fastest_lap_ms"] is not None else "—"}


def _when(ms: int) -> str:
    return datetime.fromtimestamp(ms / 1000, tz=UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
