"""Accounts (JSON): self sign-up and confirmation, staff registration, user listing, roles, disabling, self-delete."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib.auth.access import ADMIN, OPERATOR, PUBLIC, REGISTRATION, SIGNED_IN, route
from chalicelib.auth.principals import Principal, User
from chalicelib.domain.errors import InvalidInput, ServiceUnavailable
from chalicelib.domain.users import (ConfirmSignUpForm, DeleteSelfForm, ModelsEraser, OwnedDataEraser, RoleChange,
                                     SignUpForm, StaffRegistrationForm, UserService)
from chalicelib.settings import Settings, get_settings
from chalicelib.storage import clients
from chalicelib.storage.users import CognitoUserDirectory

bp = Blueprint(__name__)


def user_directory(settings: Settings | None = None) -> CognitoUserDirectory:
    settings = settings or get_settings()
    if not settings.user_pool_id or not settings.user_pool_client_id:
        raise ServiceUnavailable("Accounts are not configured (DREM_USER_POOL_ID / DREM_USER_POOL_CLIENT_ID).")
    return CognitoUserDirectory(clients.cognito(), settings.user_pool_id, settings.user_pool_client_id)


def owned_data_erasers() -> tuple[OwnedDataEraser, ...]:
    """What self-delete must clear besides the profile: the user's models."""
    from chalicelib.storage.models import build_model_service

    return (ModelsEraser(build_model_service()),)


def user_service() -> UserService:
    from chalicelib.routes.profiles import profile_service

    return UserService(user_directory(), profile_service(), owned_data_erasers())


@route(bp, "/api/signup", methods=["POST"], allow=PUBLIC)
def sign_up(principal: Principal) -> Response:
    result = user_service().sign_up(SignUpForm.model_validate(json_object(bp.current_request)))
    return Response(body=result.model_dump(exclude={"sub"}), status_code=201)


@route(bp, "/api/signup/confirm", methods=["POST"], allow=PUBLIC)
def confirm_sign_up(principal: Principal) -> dict:
    return user_service().confirm_sign_up(ConfirmSignUpForm.model_validate(json_object(bp.current_request)))


@route(bp, "/api/users", methods=["POST"], allow={ADMIN, REGISTRATION})
def register_racer(principal: User) -> Response:
    registered = user_service().register_racer(StaffRegistrationForm.model_validate(json_object(bp.current_request)))
    return Response(body=registered.model_dump(), status_code=201, headers={"Cache-Control": "no-store"})


@route(bp, "/api/users", allow={ADMIN, REGISTRATION, OPERATOR})
def list_users(principal: User) -> dict:
    query = bp.current_request.query_params or {}
    page = user_service().list_users(query.get("prefix"), _limit(query.get("limit")), query.get("next"))
    return page.model_dump()


@route(bp, "/api/users/{username}/role", methods=["PUT"], allow={ADMIN})
def change_role(principal: User, username: str) -> dict:
    return user_service().change_role(principal, username, RoleChange.model_validate(json_object(bp.current_request)))


@route(bp, "/api/users/{username}/disable", methods=["POST"], allow={ADMIN})
def disable_user(principal: User, username: str) -> dict:
    return user_service().set_enabled(principal, username, False).model_dump()


@route(bp, "/api/users/{username}/enable", methods=["POST"], allow={ADMIN})
def enable_user(principal: User, username: str) -> dict:
    return user_service().set_enabled(principal, username, True).model_dump()


@route(bp, "/api/me", methods=["DELETE"], allow=SIGNED_IN)
def delete_self(principal: User) -> dict:
    return user_service().delete_self(principal, DeleteSelfForm.model_validate(json_object(bp.current_request)))


def json_object(request) -> dict:
    """The JSON body as a dict, or a 400 that says what to send (Chalice's own error would surface as a 500)."""
    try:
        body = request.json_body
    except Exception as exc:  # chalice.BadRequestError for malformed JSON
        raise InvalidInput("The body is not valid JSON.", field="body") from exc
    if not isinstance(body, dict):
        raise InvalidInput("Send a JSON object.", field="body")
    return body


def _limit(raw: str | None) -> int:
    if raw is None:
        return 60
    if not raw.isdigit():
        raise InvalidInput("limit is a whole number.", field="limit")
    return int(raw)
