"""Sign-in, the temporary-password challenge and sign-out (browser forms; errors appear next to their field), and
the JSON token exchange for API clients (`POST /api/auth/token`, `POST /api/auth/refresh`)."""
from __future__ import annotations

from collections.abc import Mapping
from typing import Literal

from chalice import Blueprint, Response
from pydantic import BaseModel, Field

from chalicelib import services
from chalicelib.auth import cookies, known_devices
from chalicelib.auth import csrf as double_submit
from chalicelib.auth.access import PUBLIC, route
from chalicelib.auth.rate_limits import client_address, guarded_sign_in
from chalicelib.auth.revocation import REVOKED
from chalicelib.auth.tokens import unverified_claim
from chalicelib.core.errors import InvalidInput, TokenExpired
from chalicelib.core.principals import Principal
from chalicelib.domain.identity import NewPasswordChallenge, NewPasswordForm, SignInForm, Tokens, password_policy_text
from chalicelib.http_errors import retry_after_headers
from chalicelib.routes.console.forms import SHOWN_ON_FORM, error_status, field_errors, submitted
from chalicelib.routes.responses import redirect, safe_next
from chalicelib.settings import get_settings
from chalicelib.storage.sessions import CHALLENGE_TTL_S
from drem_web import render

bp = Blueprint(__name__)

_CHALLENGE_PATH = "/login/new-password"
_MISSING = "Enter your {label}."


@route(bp, "/login", allow=PUBLIC)
def login_page(principal: Principal) -> Response:
    query: Mapping[str, str] = bp.current_request.query_params or {}
    return _login_form(next_path=safe_next(query.get("next")))


@route(bp, "/login", methods=["POST"], allow=PUBLIC)
def login(principal: Principal) -> Response:
    values = submitted(bp.current_request, "username", "password", "next")
    next_path, secure = safe_next(values.get("next")), get_settings().cookie_secure
    try:
        credentials = SignInForm.model_validate(values)
        result = _sign_in(credentials)
    except SHOWN_ON_FORM as exc:
        return _login_form(exc, username=values.get("username", ""), next_path=next_path)
    if isinstance(result, NewPasswordChallenge):
        return redirect(_CHALLENGE_PATH, cookies=[_challenge_cookie(result, secure)])
    return redirect(next_path, cookies=[*_new_session(result, secure), _device_cookie(credentials.username, secure)])


@route(bp, _CHALLENGE_PATH, allow=PUBLIC)
def new_password_page(principal: Principal) -> Response:
    challenge = services.session_store().challenge(_challenge_id(bp.current_request.headers))
    if challenge is None:
        return redirect("/login")
    return _new_password_form(challenge)


@route(bp, _CHALLENGE_PATH, methods=["POST"], allow=PUBLIC)
def new_password(principal: Principal) -> Response:
    request, store = bp.current_request, services.session_store()
    challenge_id, secure = _challenge_id(request.headers), get_settings().cookie_secure
    challenge = store.challenge(challenge_id)
    if challenge is None:
        return _login_form(notice="That sign-in has expired; sign in again with your temporary password.")
    try:
        passwords = submitted(request, "new_password", "confirm_password")
        tokens = services.identity_provider().complete_new_password(challenge, _matching_new_password(passwords))
    except TokenExpired:
        return _login_form(notice="That sign-in has expired; sign in again with your temporary password.")
    except SHOWN_ON_FORM as exc:
        return _new_password_form(challenge, exc)
    store.forget_challenge(challenge_id)  # used once: the id cannot be replayed
    done = cookies.clear_cookie(cookies.CHALLENGE_COOKIE, secure=secure, path=_CHALLENGE_PATH, same_site="Strict")
    return redirect("/", cookies=[*_new_session(tokens, secure), done, _device_cookie(challenge.username, secure)])


@route(bp, "/logout", methods=["POST"], allow=PUBLIC)
def logout(principal: Principal) -> Response:
    access_token = cookies.request_cookies(bp.current_request.headers).get(cookies.SESSION_COOKIE)
    if principal.is_user and access_token:
        services.identity_provider().sign_out_everywhere(access_token)
        # Cognito revokes the refresh tokens; the access tokens already issued are revoked here.
        assert principal.sub is not None  # a signed-in user has one
        REVOKED.signed_out(services.session_store(), principal.sub, unverified_claim(access_token, "origin_jti"))
    return redirect("/login", cookies=cookies.clear_session_cookies(secure=get_settings().cookie_secure))


class RefreshRequest(BaseModel):
    refresh_token: str = Field(min_length=1, max_length=8192, description="from an earlier /api/auth/token answer")


class TokenGrant(BaseModel):
    access_token: str = Field(description="send as `Authorization: Bearer <access_token>`")
    id_token: str
    refresh_token: str | None = Field(default=None, description="exchange at /api/auth/refresh for a new one")
    expires_in: int = Field(description="seconds the access token stays valid")
    token_type: Literal["Bearer"] = "Bearer"


class ChallengeAnswer(BaseModel):
    """The account still has a temporary password: set a permanent one (in the browser) before tokens are issued."""
    challenge: Literal["NEW_PASSWORD_REQUIRED"] = "NEW_PASSWORD_REQUIRED"
    session: str


# No ambient credentials here: the password (or refresh token) in the body is the credential, so no CSRF check.
@route(bp, "/api/auth/token", methods=["POST"], allow=PUBLIC, csrf=False, body=SignInForm,
       response=TokenGrant | ChallengeAnswer, tags=("auth",))
def issue_token(principal: Principal, body: SignInForm) -> Response:
    """Exchange a username and password for Bearer tokens (for API clients and scripts)."""
    result = _sign_in(body)
    if isinstance(result, NewPasswordChallenge):
        return _no_store(ChallengeAnswer(session=result.session))
    return _no_store(TokenGrant(**result.model_dump()))


# No ambient credentials here either: the refresh token comes in the body, never from a cookie.
@route(bp, "/api/auth/refresh", methods=["POST"], allow=PUBLIC, csrf=False, body=RefreshRequest,
       response=TokenGrant, tags=("auth",))
def refresh_token(principal: Principal, body: RefreshRequest) -> Response:
    """Exchange a refresh token for a new access token."""
    return _no_store(TokenGrant(**services.identity_provider().refresh(body.refresh_token).model_dump()))


def _sign_in(credentials: SignInForm) -> Tokens | NewPasswordChallenge:
    request = bp.current_request
    # Sign-in names are case-insensitive: "ADMIN" signs in as "admin" (Cognito's pool does this itself; the
    # local one is case-sensitive, so the account's own spelling is looked up first).
    username = services.user_service().account_name(credentials.username) or credentials.username
    known = known_devices.device_id(cookies.request_cookies(request.headers).get(known_devices.DEVICE_COOKIE),
                                    username)
    return guarded_sign_in(lambda: services.identity_provider().sign_in(username, credentials.password),
                           username, client_address(request), known_device=known)


def _device_cookie(username: str, secure: bool) -> str:
    """This browser proved the password: its next right password is checked before anyone's guesses count."""
    return cookies.set_cookie(known_devices.DEVICE_COOKIE, known_devices.issue(username), secure=secure,
                              max_age=known_devices.MAX_AGE_S, same_site="Strict")


def _no_store(answer: BaseModel) -> Response:
    # Credentials must not linger in shared caches or the browser's back/forward cache.
    return Response(answer.model_dump(mode="json"), headers={"Cache-Control": "no-store"})


def _login_form(exc: Exception | None = None, *, username: str = "", next_path: str = "/",
                notice: str = "") -> Response:
    errors = field_errors(exc, "password", missing=_MISSING) if exc else {}
    return render.page("login", status=error_status(exc) if exc else 200, errors=errors,
                       username=username, next_path=next_path, notice=notice, headers=retry_after_headers(exc))


def _new_password_form(challenge: NewPasswordChallenge, exc: Exception | None = None) -> Response:
    return render.page("new_password", status=error_status(exc) if exc else 200, username=challenge.username,
                       policy=password_policy_text(),
                       errors=field_errors(exc, "new_password", missing=_MISSING) if exc else {})


def _matching_new_password(form: dict[str, str]) -> str:
    passwords = NewPasswordForm.model_validate(form)
    if passwords.new_password != passwords.confirm_password:
        raise InvalidInput("The two passwords differ.", field="confirm_password")
    return passwords.new_password


def _new_session(tokens: Tokens, secure: bool) -> list[str]:
    """Session cookies plus a CSRF token bound to the new session (a token planted before sign-in stops working)."""
    sub = unverified_claim(tokens.access_token, "sub") or ""
    secret = double_submit.session_secret(sub, unverified_claim(tokens.access_token, "origin_jti"), tokens.access_token)
    return [*cookies.session_cookies(tokens.access_token, tokens.refresh_token, tokens.expires_in, secure=secure),
            double_submit.bound_cookie(secret, secure=secure)]


def _challenge_cookie(challenge: NewPasswordChallenge, secure: bool) -> str:
    # The username and Cognito session stay on the server; the browser holds only a random id for them.
    challenge_id = services.session_store().hold_challenge(challenge)
    return cookies.set_cookie(cookies.CHALLENGE_COOKIE, challenge_id, secure=secure, path=_CHALLENGE_PATH,
                              same_site="Strict", max_age=CHALLENGE_TTL_S)


def _challenge_id(headers) -> str:
    return cookies.request_cookies(headers).get(cookies.CHALLENGE_COOKIE, "")
