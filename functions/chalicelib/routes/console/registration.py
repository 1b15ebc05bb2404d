"""The registration desk (HTML, admin and registration staff): create racer accounts one after another and show
each temporary password once, in a box that prints on its own. Same service as `POST /api/users`."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, REGISTRATION, route
from chalicelib.core.principals import User
from chalicelib.domain.countries import COUNTRY_CHOICES
from chalicelib.domain.users import RegisteredUser, StaffRegistrationForm
from chalicelib.htmx import is_htmx
from chalicelib.routes.console.forms import SHOWN_ON_FORM, error_status, field_errors, submitted, with_country_code
from drem_web import render

bp = Blueprint(__name__)

DESK_STAFF = {ADMIN, REGISTRATION}
_FIELDS = ("display_name", "username", "email", "country_code")


@route(bp, "/console/registration", allow=DESK_STAFF)
def registration_page(principal: User) -> Response:
    return _desk()


@route(bp, "/console/registration", methods=["POST"], allow=DESK_STAFF)
def register_racer(principal: User) -> Response:
    values = submitted(bp.current_request, *_FIELDS)
    try:
        form = StaffRegistrationForm.model_validate(with_country_code(values))
        registered = services.user_service().register_racer(form)
    except SHOWN_ON_FORM as exc:
        return _desk(values, field_errors(exc, "username"), error_status(exc))
    # The next racer at an event usually comes from the same country: keep it, clear the rest.
    return _desk({"country_code": registered.country_code}, registered=registered)


def _desk(values: dict[str, str] | None = None, errors: dict[str, str] | None = None, status: int = 200,
          registered: RegisteredUser | None = None) -> Response:
    context = dict(values={name: (values or {}).get(name, "") for name in _FIELDS}, countries=COUNTRY_CHOICES,
                   errors=errors or {}, registered=registered, status=201 if registered else status,
                   # The temporary password must not stay in any cache.
                   headers={"Cache-Control": "no-store"})
    if is_htmx(bp.current_request):
        return render.fragment("console/registration_desk", **context)
    return render.page("console/registration", **context)
