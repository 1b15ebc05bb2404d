"""Racer screens (HTML): sign up and confirm, change password, profile, my models (upload, live status, delete) and
my races. Every form posts to the same domain services as the JSON API and shows refusals next to the field.

Per-object rule: everything here acts on the caller's own account, profile, models and races (the services take
the caller from the session; a model id of another racer answers 403 through `chalicelib.domain.racer_models`)."""
from __future__ import annotations

from urllib.parse import quote

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth import cookies
from chalicelib.auth.access import PUBLIC, SIGNED_IN, route
from chalicelib.auth.rate_limits import client_address, guarded_sign_up
from chalicelib.core.principals import Principal, User
from chalicelib.domain.countries import COUNTRY_CHOICES
from chalicelib.domain.identity import password_policy_text
from chalicelib.domain.passwords import PasswordChangeForm
from chalicelib.domain.profiles import HIGHLIGHT_PALETTE, ProfileUpdate
from chalicelib.domain.racer_models import ListQuery, ModelStatus
from chalicelib.domain.users import ConfirmSignUpForm, SignUpForm
from chalicelib.htmx import is_htmx
from chalicelib.http_errors import retry_after_headers
from chalicelib.routes.console.forms import (
    SHOWN_ON_FORM,
    error_status,
    field_errors,
    redirect,
    submitted,
    with_country_code,
)
from chalicelib.routes.console.notices import done_notice
from drem_leaderboard.ranking import DEFAULT_HIGHLIGHT_COLOUR
from drem_web import render

bp = Blueprint(__name__)

_SIGN_UP_FIELDS = ("display_name", "username", "email", "country_code", "password")
_MY_MODELS_LIMIT = 100


# --- sign up and confirm (public) -------------------------------------------------------------------------------

@route(bp, "/signup", allow=PUBLIC)
def signup_page(principal: Principal) -> Response:
    return _signup_form()


@route(bp, "/signup", methods=["POST"], allow=PUBLIC)
def signup(principal: Principal) -> Response:
    values = submitted(bp.current_request, *_SIGN_UP_FIELDS)
    try:
        body = SignUpForm.model_validate(with_country_code(values))
        result = guarded_sign_up(lambda: services.user_service().sign_up(body), client_address(bp.current_request))
    except SHOWN_ON_FORM as exc:
        return _signup_form(values, field_errors(exc, "username"), error_status(exc), retry_after_headers(exc))
    if result.confirmed:  # a local stack: no code to wait for
        return render.page("console/confirm", username=result.username, errors={}, confirmed=True)
    return redirect(f"/signup/confirm?username={quote(result.username)}")


@route(bp, "/signup/confirm", allow=PUBLIC)
def confirm_page(principal: Principal) -> Response:
    username = (bp.current_request.query_params or {}).get("username", "")
    return render.page("console/confirm", username=username[:128], errors={}, confirmed=False)


@route(bp, "/signup/confirm", methods=["POST"], allow=PUBLIC)
def confirm(principal: Principal) -> Response:
    values = submitted(bp.current_request, "username", "code")
    try:
        services.user_service().confirm_sign_up(ConfirmSignUpForm.model_validate(values))
    except SHOWN_ON_FORM as exc:
        return render.page("console/confirm", status=error_status(exc), username=values.get("username", ""),
                           errors=field_errors(exc, "code"), confirmed=False)
    return render.page("console/confirm", username=values["username"].strip(), errors={}, confirmed=True)


# --- password and profile (the caller's own) ----------------------------------------------------------------------

@route(bp, "/console/password", allow=SIGNED_IN)
def password_page(principal: User) -> Response:
    return _password_form()


@route(bp, "/console/password", methods=["POST"], allow=SIGNED_IN)
def change_password(principal: User) -> Response:
    request = bp.current_request
    access_token = cookies.request_cookies(request.headers).get(cookies.SESSION_COOKIE)
    try:
        form = PasswordChangeForm.model_validate(
            submitted(request, "current_password", "new_password", "confirm_password"))
        done = services.password_service().change(access_token, form)
    except SHOWN_ON_FORM as exc:
        return _password_form(field_errors(exc, "current_password"), error_status(exc))
    return _password_form(notice=done)


@route(bp, "/console/profile", allow=SIGNED_IN)
def profile_page(principal: User) -> Response:
    return _profile_form(services.profile_service().own(principal))


@route(bp, "/console/profile", methods=["POST"], allow=SIGNED_IN)
def update_profile(principal: User) -> Response:
    service = services.profile_service()
    values = submitted(bp.current_request, "highlight_colour", "avatar", "country_code", "display_name")
    if not values.get("display_name", "").strip():  # left empty: the name stays as it was
        values.pop("display_name", None)
    try:
        saved = service.update_own(principal, ProfileUpdate.model_validate(with_country_code(values, required=False)))
    except SHOWN_ON_FORM as exc:
        return _profile_form(service.own(principal), field_errors(exc, "highlight_colour"), error_status(exc),
                             typed_country=values.get("country_code", ""), typed_name=values.get("display_name", ""))
    return _profile_form(saved, notice="Your profile is saved; the leaderboards show it now.")


# --- my models ----------------------------------------------------------------------------------------------------

@route(bp, "/console/my-models", allow=SIGNED_IN)
def my_models(principal: User) -> Response:
    service = services.model_service()
    return render.page("console/my_models", models=_own_models(service, principal),
                       max_bytes=service.max_upload_bytes, flash=done_notice(bp.current_request))


@route(bp, "/console/my-models/rows", allow=SIGNED_IN)
def my_model_rows(principal: User) -> Response:
    return render.fragment("console/my_model_rows", models=_own_models(services.model_service(), principal))


@route(bp, "/console/my-models/{model_id}/row", allow=SIGNED_IN)
def my_model_row(principal: User, model_id: str) -> Response:
    return render.fragment("console/my_model_row", model=services.model_service().get(_only_own(principal), model_id))


@route(bp, "/console/my-models/{model_id}/delete", methods=["POST"], allow=SIGNED_IN)
def delete_my_model(principal: User, model_id: str) -> Response:
    deleted = services.model_service().delete(_only_own(principal), model_id)
    if is_htmx(bp.current_request):
        return render.fragment("console/my_model_deleted", model=deleted)
    return redirect("/console/my-models", done="model-deleted")


# --- my races -----------------------------------------------------------------------------------------------------

@route(bp, "/console/my-races", allow=SIGNED_IN)
def my_races(principal: User) -> Response:
    events = {event.event_id: event for event in services.event_service().list_events()}
    return render.page("console/my_races", races=list(reversed(services.race_service().my_races(principal))),
                       events=events)


@route(bp, "/console/my-races/{event_id}/{race_id}", allow=SIGNED_IN)
def my_race_laps(principal: User, event_id: str, race_id: str) -> Response:
    race = services.race_service().get_race(_only_own(principal), event_id, race_id)
    return render.fragment("console/race_laps", race=race)


# --- helpers ------------------------------------------------------------------------------------------------------

def _only_own(principal: User) -> User:
    """The caller without staff roles: "my" screens list and act on the caller's own things even for admins, and
    another racer's id still answers 403 from the service's ownership rule."""
    return User(sub=principal.sub, username=principal.username, groups=frozenset())


def _own_models(service, principal: User) -> list:
    page = service.list_models(_only_own(principal), ListQuery(limit=_MY_MODELS_LIMIT))
    return [m for m in page.models if m.status is not ModelStatus.DELETED]


def _signup_form(values: dict[str, str] | None = None, errors: dict[str, str] | None = None, status: int = 200,
                 headers: dict[str, str] | None = None) -> Response:
    # The password is never sent back into the page.
    shown = {name: (values or {}).get(name, "") for name in _SIGN_UP_FIELDS if name != "password"}
    return render.page("console/signup", status=status, values=shown, errors=errors or {}, countries=COUNTRY_CHOICES,
                       policy=password_policy_text(), headers=headers)


def _password_form(errors: dict[str, str] | None = None, status: int = 200, notice: str = "") -> Response:
    return render.page("console/password", status=status, notice=notice, errors=errors or {},
                       policy=password_policy_text())


def _profile_form(profile, errors: dict[str, str] | None = None, status: int = 200, notice: str = "",
                  typed_country: str = "", typed_name: str = "") -> Response:
    return render.page("console/profile", status=status, profile=profile, palette=HIGHLIGHT_PALETTE, notice=notice,
                       display_name=typed_name or profile.display_name or profile.username or "",
                       country=typed_country or profile.country_code or "", countries=COUNTRY_CHOICES,
                       # Before the first save the boards show the default colour: the form says so by selecting it.
                       shown_colour=profile.highlight_colour or DEFAULT_HIGHLIGHT_COLOUR, errors=errors or {})
