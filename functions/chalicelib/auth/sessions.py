"""Browser sessions and bearer tokens → a verified Principal (renewing an expired session from its refresh token)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

from chalicelib.auth.cookies import REFRESH_COOKIE, SESSION_COOKIE, clear_session_cookies, session_cookies
from chalicelib.auth.csrf import session_secret
from chalicelib.auth.revocation import REVOKED, RevocationStore
from chalicelib.auth.tokens import VerifiedToken, verify_token
from chalicelib.core.errors import NotAuthenticated, TokenExpired
from chalicelib.core.principals import ANONYMOUS, Principal, User, verify_device_credential
from chalicelib.settings import Settings, get_settings


class TokenRenewer(Protocol):
    def refresh(self, refresh_token: str) -> RenewedTokens: ...


class RenewedTokens(Protocol):
    @property
    def access_token(self) -> str: ...
    @property
    def expires_in(self) -> int: ...


class SessionBackends(Protocol):
    """Where sessions are kept and renewed; the composition root (chalicelib.services) installs its own with
    `use_session_backends`, so this module needs nothing above the auth layer."""
    def session_store(self) -> RevocationStore: ...
    def identity_provider(self, settings: Settings) -> TokenRenewer: ...


_backends: SessionBackends | None = None


def use_session_backends(backends: SessionBackends) -> None:
    global _backends
    _backends = backends


def _installed() -> SessionBackends:
    if _backends is None:
        raise RuntimeError("No session backends installed: import chalicelib.services (the composition root) first.")
    return _backends


@dataclass
class ResolvedCaller:
    principal: Principal
    # "header" (Bearer/Device: exempt from CSRF), "cookie" or "none"
    via: str
    set_cookies: list[str] = field(default_factory=list)
    # For a cookie session: what its CSRF token is bound to (chalicelib.auth.csrf.session_secret), taken from the
    # very access token the request runs as.
    csrf_secret: str | None = None


def _cookie_caller(token: VerifiedToken, raw: str, set_cookies: list[str] | None = None) -> ResolvedCaller:
    secret = session_secret(token.sub, _text(token.claims.get("origin_jti")), raw)
    return ResolvedCaller(user_from(token), "cookie", set_cookies or [], csrf_secret=secret)


def _text(value: object) -> str | None:
    return str(value) if value else None


def user_from(token: VerifiedToken) -> User:
    return User(sub=token.sub, username=token.username, groups=token.groups)


class TokenRevoked(NotAuthenticated):
    """Signed and unexpired, but its user signed out or changed since: a browser may still renew it."""


def current_token(token: str, settings: Settings) -> VerifiedToken:
    """A verified access token that has not been revoked since it was issued (chalicelib.auth.revocation)."""
    verified = verify_token(token, settings)
    try:
        REVOKED.require_current(_installed().session_store(), verified.sub, verified.claims)
    except NotAuthenticated as exc:
        raise TokenRevoked(exc.message) from None
    return verified


def resolve_caller(headers: Mapping[str, str], cookies: Mapping[str, str]) -> ResolvedCaller:
    settings = get_settings()
    authorization = headers.get("authorization")
    if authorization is not None:
        scheme, _, credential = authorization.strip().partition(" ")
        if scheme.lower() == "bearer" and credential.strip():
            return ResolvedCaller(user_from(current_token(credential.strip(), settings)), "header")
        if scheme.lower() == "device" and credential.strip():
            return ResolvedCaller(verify_device_credential(credential.strip()), "header")
        raise NotAuthenticated("Use 'Authorization: Bearer <access token>'.")
    return _from_session_cookies(cookies, settings)


def _from_session_cookies(cookies: Mapping[str, str], settings: Settings) -> ResolvedCaller:
    access, refresh = cookies.get(SESSION_COOKIE), cookies.get(REFRESH_COOKIE)
    if not access and not refresh:
        return ResolvedCaller(ANONYMOUS, "none")
    if access:
        try:
            return _cookie_caller(current_token(access, settings), access)
        except (TokenExpired, TokenRevoked):
            pass  # renew below (after a role change the refresh token brings the new groups)
        except NotAuthenticated:
            return _signed_out(settings)
    if not refresh:
        return _signed_out(settings)
    try:
        tokens = _installed().identity_provider(settings).refresh(refresh)
        renewed_token = current_token(tokens.access_token, settings)
    except NotAuthenticated:
        return _signed_out(settings)
    renewed = session_cookies(tokens.access_token, None, tokens.expires_in, secure=settings.cookie_secure)
    return _cookie_caller(renewed_token, tokens.access_token, renewed)


def _signed_out(settings: Settings) -> ResolvedCaller:
    # A session that cannot be verified or renewed is dropped, so the browser stops sending it.
    return ResolvedCaller(ANONYMOUS, "cookie", clear_session_cookies(secure=settings.cookie_secure))
