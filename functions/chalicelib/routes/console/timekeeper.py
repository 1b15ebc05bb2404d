"""Operator console: the timekeeper screen. The race is the track's live race on the server (`RaceService`), so a
reload or a second tablet shows the same race; the screen polls its state fragment about once a second."""
from __future__ import annotations

import re

from chalice import Blueprint, Response
from pydantic import BaseModel, ConfigDict, Field

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, route
from chalicelib.core.principals import User
from chalicelib.domain.races import CreateRaceInput
from chalicelib.routes.console.forms import SHOWN_ON_FORM, checkbox, error_status, field_errors, optional, submitted
from chalicelib.views.on_deck_panel import queue_panel
from chalicelib.views.timekeeper_desk import ScreenCommand, TimekeeperDesk, TimekeeperScreen
from drem_web import render

bp = Blueprint(__name__)

TIMEKEEPERS = {ADMIN, OPERATOR}
_RACE_OVER = {"submit", "discard"}
# The start of a sign-in name; anything else typed (a display name, a space) just finds nobody.
_PREFIX = re.compile(r"^[A-Za-z0-9_.-]{0,64}$")


class RacerSearch(BaseModel):
    """The racer field's own value: htmx sends a GET's triggering input under its name (no script needed, so the
    suggestions work under the site's `script-src 'self'`); `prefix` for API callers."""
    model_config = ConfigDict(extra="ignore")
    prefix: str = Field(default="", max_length=256)
    racer_username: str = Field(default="", max_length=256)
    queue_racer: str = Field(default="", max_length=256)

    @property
    def typed(self) -> str:
        return (self.prefix or self.racer_username or self.queue_racer).strip()


class ProfileColours:
    def __init__(self) -> None:
        self._profiles = services.profile_service()

    def highlight_colour(self, sub: str) -> str | None:
        public = self._profiles.public_by_sub(sub)
        return public.highlight_colour if public else None

    def shown_name(self, sub: str, username: str) -> str:
        public = self._profiles.public_by_sub(sub)
        return (public.display_name or public.username) if public else username


def desk() -> TimekeeperDesk:
    # The race service's clock, looked up per call, so the screen and the race agree on "now".
    return TimekeeperDesk(services.race_service(), services.race_store(), services.device_service(), ProfileColours(),
                          lambda: services.now_ms())


@route(bp, "/console/timekeeper", allow=TIMEKEEPERS)
def choose_track_page(principal: User) -> Response:
    return render.page("console/timekeeper_pick", events=services.event_service().list_events())


@route(bp, "/console/timekeeper/racers", allow=TIMEKEEPERS, query=RacerSearch)
def racer_options(principal: User, query: RacerSearch) -> Response:
    typed = query.typed
    users = services.user_service().list_users(typed or None, 20).users if _PREFIX.match(typed) else []
    shown = services.profile_service().public_by_subs([u.sub for u in users])
    options = [(u.username, shown[u.sub].display_name if u.sub in shown else u.username) for u in users]
    return render.fragment("console/tk_racer_options", options=options)


@route(bp, "/console/timekeeper/{event_id}/{track_id}", allow=TIMEKEEPERS)
def timekeeper_page(principal: User, event_id: str, track_id: str) -> Response:
    return render.page("console/timekeeper", screen=desk().screen(event_id, track_id), errors={}, setup={},
                       queue=queue_panel(services.on_deck(), services.profile_service().public_by_subs, event_id,
                                         track_id), queue_errors={}, queue_values={})


@route(bp, "/console/timekeeper/{event_id}/{track_id}/state", allow=TIMEKEEPERS)
def race_state(principal: User, event_id: str, track_id: str) -> Response:
    return _state(desk().screen(event_id, track_id))


@route(bp, "/console/timekeeper/{event_id}/{track_id}/races", methods=["POST"], allow=TIMEKEEPERS)
def start_race(principal: User, event_id: str, track_id: str) -> Response:
    values = submitted(bp.current_request, "racer_username", "car", "raced_by_proxy", "override_max_runs")
    data = {"track_id": track_id, "racer_username": values.get("racer_username", "").strip(),
            "car": optional(values.get("car")), "raced_by_proxy": checkbox(values, "raced_by_proxy"),
            "override_max_runs": checkbox(values, "override_max_runs")}
    try:
        screen = desk().start_race(principal, event_id, CreateRaceInput.model_validate(data))
    except SHOWN_ON_FORM as exc:
        errors = field_errors(exc, rename=lambda name: "racer_username" if name == "username" else name,
                              missing_object_field="racer_username")  # a racer nobody registered
        return _state(desk().screen(event_id, track_id), errors, values, error_status(exc))
    # Off the queue if they were in line; the car just taken may have held the next model.
    services.on_deck().started_elsewhere(principal, event_id, track_id, str(data["racer_username"]))
    return _state(screen)


@route(bp, "/console/timekeeper/{event_id}/{track_id}/commands", methods=["POST"], allow=TIMEKEEPERS)
def press_button(principal: User, event_id: str, track_id: str) -> Response:
    values = submitted(bp.current_request, "race_id", "kind", "lap_id", "is_valid")  # a button's hx-vals
    try:
        screen = desk().press(principal, event_id, track_id, ScreenCommand.model_validate(values))
    except SHOWN_ON_FORM as exc:
        return _state(desk().screen(event_id, track_id), field_errors(exc), {}, error_status(exc))
    if values.get("kind") in _RACE_OVER:  # the car is free again: the next racer's model goes to it now
        services.on_deck().preload_head(principal, event_id, track_id)
    return _state(screen)


def _state(screen: TimekeeperScreen, errors: dict[str, str] | None = None, setup: dict[str, str] | None = None,
           status: int = 200) -> Response:
    return render.fragment("console/tk_state", status=status, screen=screen, errors=errors or {}, setup=setup or {})
