"""Accounts (JSON): self sign-up and confirmation, staff registration, user listing, roles, disabling, confirming a
sign-up for the racer, self-delete."""
from __future__ import annotations

from collections.abc import Mapping

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, PUBLIC, REGISTRATION, SIGNED_IN, route
from chalicelib.auth.rate_limits import client_address, guarded_sign_up
from chalicelib.core.principals import Principal, User
from chalicelib.domain.numbers import whole_number
from chalicelib.domain.users import (
    MAX_PAGE,
    ConfirmSignUpForm,
    DeleteSelfForm,
    DirectoryUser,
    RegisteredUser,
    RoleChange,
    SignUpForm,
    StaffRegistrationForm,
    UserPage,
)

bp = Blueprint(__name__)


@route(bp, "/api/signup", methods=["POST"], allow=PUBLIC, body=SignUpForm, status_code=201)
def sign_up(principal: Principal, body: SignUpForm) -> Response:
    result = guarded_sign_up(lambda: services.user_service().sign_up(body), client_address(bp.current_request))
    return Response(body=result.model_dump(exclude={"sub"}), status_code=201)


@route(bp, "/api/signup/confirm", methods=["POST"], allow=PUBLIC, body=ConfirmSignUpForm)
def confirm_sign_up(principal: Principal, body: ConfirmSignUpForm) -> dict:
    return services.user_service().confirm_sign_up(body)


@route(bp, "/api/users", methods=["POST"], allow={ADMIN, REGISTRATION}, body=StaffRegistrationForm,
       response=RegisteredUser, status_code=201)
def register_racer(principal: User, body: StaffRegistrationForm) -> Response:
    registered = services.user_service().register_racer(body)
    return Response(body=registered.model_dump(), status_code=201, headers={"Cache-Control": "no-store"})


@route(bp, "/api/users", allow={ADMIN, REGISTRATION, OPERATOR}, response=UserPage)
def list_users(principal: User) -> dict:
    query: Mapping[str, str] = bp.current_request.query_params or {}
    page = services.user_service().list_users(query.get("prefix"), _limit(query.get("limit")), query.get("next"))
    return page.model_dump()


@route(bp, "/api/users/{username}/role", methods=["PUT"], allow={ADMIN}, body=RoleChange)
def change_role(principal: User, username: str, body: RoleChange) -> dict:
    return services.user_service().change_role(principal, username, body)


@route(bp, "/api/users/{username}/disable", methods=["POST"], allow={ADMIN}, response=DirectoryUser)
def disable_user(principal: User, username: str) -> dict:
    return services.user_service().set_enabled(principal, username, False).model_dump()


@route(bp, "/api/users/{username}/enable", methods=["POST"], allow={ADMIN}, response=DirectoryUser)
def enable_user(principal: User, username: str) -> dict:
    return services.user_service().set_enabled(principal, username, True).model_dump()


@route(bp, "/api/users/{username}/confirm", methods=["POST"], allow={ADMIN}, response=DirectoryUser)
def confirm_user(principal: User, username: str) -> dict:
    """Confirm a self sign-up whose emailed code never arrived (409 for an account not waiting for one)."""
    return services.user_service().confirm_account(username).model_dump()


@route(bp, "/api/me", methods=["DELETE"], allow=SIGNED_IN, body=DeleteSelfForm)
def delete_self(principal: User, body: DeleteSelfForm) -> dict:
    return services.user_service().delete_self(principal, body)


def _limit(raw: str | None) -> int:
    if raw is None:
        return MAX_PAGE
    return whole_number(raw, field="limit", message=f"limit is a whole number between 1 and {MAX_PAGE}.",
                        minimum=1, maximum=MAX_PAGE)
