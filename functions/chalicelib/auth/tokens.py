"""Verifying Cognito JWTs in the app (API Gateway's Cognito authorizer is not enforced by `chalice local`).

Accepted: RS256 only, signed by the right key, with our issuer, the right `token_use`, our app client (`client_id`
for access tokens, `aud` for id tokens) and an `exp` in the future.

The right key: on AWS, a key from the pool's JWKS (looked up by `kid`). Locally, ONLY the installation's own key
(`settings.token_key_file`, generated at the first `drem up`), whatever the local JWKS says: stock moto signs every
pool with a key that ships inside the moto package, so anything it publishes proves nothing.
"""
from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import requests
from jose import jwt
from jose.exceptions import ExpiredSignatureError, JWTError

from chalicelib.core.errors import NotAuthenticated, ServiceUnavailable, TokenExpired
from chalicelib.settings import Settings

_ALGORITHM = "RS256"
_JWKS_TIMEOUT_S = 3.0
# An unknown kid triggers at most one re-fetch per interval, so forged kids cannot hammer the JWKS endpoint.
_MIN_REFETCH_INTERVAL_S = 30.0


@dataclass(frozen=True)
class VerifiedToken:
    claims: dict[str, Any]

    @property
    def sub(self) -> str:
        return str(self.claims["sub"])

    @property
    def username(self) -> str:
        return str(self.claims.get("username") or self.claims.get("cognito:username") or self.claims["sub"])

    @property
    def groups(self) -> frozenset[str]:
        groups = self.claims.get("cognito:groups") or []
        return frozenset(str(g) for g in groups) if isinstance(groups, list) else frozenset()


class JwksCache:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._keys: dict[str, dict[str, dict[str, Any]]] = {}
        self._fetched_at: dict[str, float] = {}

    def key_for(self, jwks_url: str, kid: str) -> dict[str, Any] | None:
        with self._lock:
            if jwks_url not in self._keys:
                self._fetch(jwks_url)
            key = self._keys[jwks_url].get(kid)
            if key is None and time.monotonic() - self._fetched_at[jwks_url] >= _MIN_REFETCH_INTERVAL_S:
                self._fetch(jwks_url)  # keys rotate: one re-fetch before giving up on this kid
                key = self._keys[jwks_url].get(kid)
            return key

    def clear(self) -> None:
        with self._lock:
            self._keys.clear()
            self._fetched_at.clear()

    def _fetch(self, jwks_url: str) -> None:
        try:
            reply = requests.get(jwks_url, timeout=_JWKS_TIMEOUT_S)
            reply.raise_for_status()
            keys = reply.json()["keys"]
        except (requests.RequestException, ValueError, KeyError, TypeError) as exc:
            raise ServiceUnavailable("The sign-in service's signing keys cannot be fetched.") from exc
        self._keys[jwks_url] = {k["kid"]: k for k in keys if isinstance(k, dict) and "kid" in k}
        self._fetched_at[jwks_url] = time.monotonic()


JWKS = JwksCache()


class PinnedKey:
    """The installation key from its file, read once per path (it never changes while the stack runs)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._keys: dict[Path, dict[str, Any]] = {}

    def key_for(self, path: Path, kid: str) -> dict[str, Any] | None:
        with self._lock:
            key = self._keys.get(path)
            if key is None:
                key = self._keys[path] = _public_half(path)
        return key if kid == key["kid"] else None

    def clear(self) -> None:
        with self._lock:
            self._keys.clear()


def _public_half(path: Path) -> dict[str, Any]:
    try:
        private = json.loads(path.read_text())
        return {"kty": "RSA", "alg": _ALGORITHM, "kid": str(private["kid"]), "n": private["n"], "e": private["e"]}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ServiceUnavailable("The installation's token signing key cannot be read; "
                                 "restart with `drem up`.") from exc


PINNED = PinnedKey()


def verify_token(token: str, settings: Settings, token_use: Literal["access", "id"] = "access",
                 jwks: JwksCache = JWKS) -> VerifiedToken:
    if not settings.user_pool_id or not settings.user_pool_client_id:
        raise ServiceUnavailable("Sign-in is not configured (DREM_USER_POOL_ID / DREM_USER_POOL_CLIENT_ID).")
    try:
        header = jwt.get_unverified_header(token)
    except JWTError as exc:
        raise NotAuthenticated("The token is not a JWT.") from exc
    if header.get("alg") != _ALGORITHM:
        raise NotAuthenticated("The token is not signed with RS256.")
    kid = str(header.get("kid", ""))
    if settings.token_key_file is not None:
        key = PINNED.key_for(settings.token_key_file, kid)
    else:
        key = jwks.key_for(settings.jwks_url, kid)
    if key is None:
        raise NotAuthenticated("The token is signed by an unknown key.")
    try:
        claims = jwt.decode(
            token, key, algorithms=[_ALGORITHM], issuer=settings.issuer,
            audience=settings.user_pool_client_id if token_use == "id" else None,
            options={"verify_aud": token_use == "id", "verify_at_hash": False, "require_exp": True,
                     "require_iss": True, "require_sub": True},
        )
    except ExpiredSignatureError as exc:
        raise TokenExpired("The token has expired.") from exc
    except JWTError as exc:
        raise NotAuthenticated(f"The token is not valid ({exc}).") from exc
    if claims.get("token_use") != token_use:
        raise NotAuthenticated(f"An {token_use} token is required.")
    if token_use == "access" and claims.get("client_id") != settings.user_pool_client_id:
        raise NotAuthenticated("The token was issued to another app client.")
    return VerifiedToken(claims)


def unverified_claim(token: str, name: str) -> str | None:
    """A claim of a token the caller has already verified (e.g. the session cookie this request was accepted with)."""
    try:
        value = jwt.get_unverified_claims(token).get(name)
    except JWTError:
        return None
    return str(value) if value is not None else None
