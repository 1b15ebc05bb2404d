"""User administration (HTML, admins only): search as you type, change a user's role, disable and enable, confirm a
self sign-up whose emailed code never arrived.
Same service as the JSON routes under /api/users; an admin cannot change or disable themselves (the service says
so, next to the row)."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, route
from chalicelib.core.principals import USER_ROLES, User
from chalicelib.domain.users import DirectoryUser, RoleChange
from chalicelib.routes.console.forms import SHOWN_ON_FORM, error_status, field_errors, submitted
from drem_web import labels, render

bp = Blueprint(__name__)

ROLE_CHOICES = sorted(role.value for role in USER_ROLES)


@route(bp, "/console/users", allow={ADMIN})
def users_page(principal: User) -> Response:
    query = _query()
    try:
        rows = _rows(query)
    except SHOWN_ON_FORM as exc:
        return render.page("console/users", status=error_status(exc), query=query, rows=[],
                           errors=_search_error(exc), roles=ROLE_CHOICES)
    return render.page("console/users", query=query, rows=rows, errors={}, roles=ROLE_CHOICES)


@route(bp, "/console/users/rows", allow={ADMIN})
def user_rows(principal: User) -> Response:
    try:
        return render.fragment("console/user_rows", rows=_rows(_query()), roles=ROLE_CHOICES, errors={})
    except SHOWN_ON_FORM as exc:
        return render.fragment("console/user_rows", status=error_status(exc), rows=[], roles=ROLE_CHOICES,
                               errors=_search_error(exc))


@route(bp, "/console/users/{username}/role", methods=["POST"], allow={ADMIN})
def change_role(principal: User, username: str) -> Response:
    change = submitted(bp.current_request, "role")
    return _act(username, lambda: services.user_service().change_role(principal, username,
                                                                       RoleChange.model_validate(change)),
                done=f"{username}'s role is now {labels.label(change.get('role', ''))}.")


@route(bp, "/console/users/{username}/disable", methods=["POST"], allow={ADMIN})
def disable_user(principal: User, username: str) -> Response:
    return _act(username, lambda: services.user_service().set_enabled(principal, username, False),
                done=f"{username} is disabled and cannot sign in.")


@route(bp, "/console/users/{username}/enable", methods=["POST"], allow={ADMIN})
def enable_user(principal: User, username: str) -> Response:
    return _act(username, lambda: services.user_service().set_enabled(principal, username, True),
                done=f"{username} is enabled and can sign in again.")


@route(bp, "/console/users/{username}/confirm", methods=["POST"], allow={ADMIN})
def confirm_user(principal: User, username: str) -> Response:
    """A self sign-up waiting for an emailed code that never came: staff confirm it for the racer."""
    return _act(username, lambda: services.user_service().confirm_account(username),
                done=f"{username} is confirmed and can sign in now.")


def _act(username: str, action, done: str) -> Response:  # noqa: ANN001 - a thunk
    """Run the service call; answer with the user's refreshed row and, in it, what was done or the refusal."""
    try:
        action()
    except SHOWN_ON_FORM as exc:
        return render.fragment("console/user_row", status=error_status(exc), row=_row(username),
                               roles=ROLE_CHOICES, row_error=field_errors(exc, "role").popitem()[1])
    return render.fragment("console/user_row", row=_row(username), roles=ROLE_CHOICES, row_error="", row_notice=done)


def _search_error(exc: Exception) -> dict[str, str]:
    # The service names its `prefix` parameter; on this page that is the search box `q`.
    return {"q": " ".join(field_errors(exc, "q").values())}


def _query() -> str:
    return ((bp.current_request.query_params or {}).get("q") or "").strip()[:128]


def _rows(prefix: str) -> list[dict]:
    page = services.user_service().list_users(prefix or None)
    directory = services.user_directory()
    return [_with_groups(user, directory.groups_of(user.username)) for user in page.users]


def _row(username: str) -> dict:
    directory = services.user_directory()
    return _with_groups(directory.get_user(username), directory.groups_of(username))


def _with_groups(user: DirectoryUser, groups: list[str]) -> dict:
    role = next((g for g in groups if g in ROLE_CHOICES), "")
    return {"user": user, "groups": groups, "role": role}
