"""Make moto's Cognito behave like a real, private user pool where drem's security depends on it.

1. Signing key. moto signs every pool's tokens with the RSA key shipped in the package
   (moto/cognitoidp/models.py: `CognitoIdpUserPool.__init__` loads resources/jwks-private.json into
   `self.json_web_key`; `create_jwt` signs with it under the header `{"kid": "dummy"}`; responses.py
   `CognitoIdpJsonWebKeyResponse` serves resources/jwks-public.json). Here every pool signs with the installation's
   key (drem_local.token_key) under its own `kid`, and the JWKS endpoint publishes that key's public half.
   `json_web_key` becomes a class property, so pools unpickled from older snapshots (which hold moto's key in their
   `__dict__`) sign with the installation key too.
2. The NEW_PASSWORD_REQUIRED session is bound to its user. Real Cognito answers `NotAuthorizedException: Invalid
   session for the user.` when USERNAME differs from the user the session was issued to; moto
   (`CognitoIdpBackend.respond_to_auth_challenge`) ignores the session's user and sets the password of whichever
   USERNAME it is sent.
3. No sign-up confirmation code exists offline (nothing is emailed), so every code is wrong. moto's
   `confirm_sign_up` accepts any code (it never receives it). drem confirms local self sign-ups itself
   (AdminConfirmSignUp, see chalicelib.domain.users) instead.
"""
from __future__ import annotations

import json
from typing import Any

_ORIGINALS: dict[str, Any] = {}


def install(private_jwk: dict[str, Any]) -> None:
    """Patch moto's Cognito (in this process) to sign with `private_jwk`; idempotent, `uninstall()` undoes it."""
    from joserfc import jwk as joserfc_jwk
    from joserfc import jwt as joserfc_jwt
    from moto.cognitoidp import models, responses
    from moto.cognitoidp.exceptions import CodeMismatchException, NotAuthorizedError

    from drem_local.token_key import public_jwk

    uninstall()
    key = joserfc_jwk.RSAKey.import_key({k: v for k, v in private_jwk.items() if k not in {"kid", "alg", "use"}})
    kid = private_jwk["kid"]
    jwks_body = json.dumps({"keys": [public_jwk(private_jwk)]}).encode()

    class InstallationSigner:
        """Stands in for joserfc's `jwt` module inside moto.cognitoidp.models: same encode, our key and kid."""

        def __getattr__(self, name: str) -> Any:
            return getattr(joserfc_jwt, name)

        @staticmethod
        def encode(header: dict[str, Any], claims: dict[str, Any], _key: Any = None, *args: Any, **kw: Any) -> str:
            return joserfc_jwt.encode({**header, "kid": kid, "alg": "RS256"}, claims, key, *args, **kw)

    class InstallationKeyLoader:
        """Stands in for joserfc's `jwk` module inside moto.cognitoidp.models, whose one use is a new pool importing
        moto's shipped key into `json_web_key` (0.1-0.3 s of RSA arithmetic per pool), which the property below
        discards anyway: the import answers with the installation key at once."""

        class RSAKey:
            @staticmethod
            def import_key(*_args: Any, **_kwargs: Any) -> Any:
                return key

        def __getattr__(self, name: str) -> Any:
            return getattr(joserfc_jwk, name)

    pool_class, backend_class = models.CognitoIdpUserPool, models.CognitoIdpBackend
    _ORIGINALS.update(jwk=models.jwk, jwt=models.jwt, pool_key=pool_class.__dict__.get("json_web_key"),
                      jwks=responses.CognitoIdpJsonWebKeyResponse.json_web_key,
                      respond=backend_class.respond_to_auth_challenge, confirm=backend_class.confirm_sign_up)
    models.jwt = InstallationSigner()
    models.jwk = InstallationKeyLoader()
    pool_class.json_web_key = property(lambda self: key, lambda self, value: None)
    responses.CognitoIdpJsonWebKeyResponse.json_web_key = jwks_body
    original_respond = backend_class.respond_to_auth_challenge

    def respond_to_auth_challenge(self: Any, session: str, client_id: str, challenge_name: str,
                                  challenge_responses: dict[str, str]) -> dict[str, Any]:
        if challenge_name == "NEW_PASSWORD_REQUIRED" and session in self.sessions:
            session_user = self.sessions[session][0]
            if (challenge_responses or {}).get("USERNAME") != session_user:
                raise NotAuthorizedError("Invalid session for the user.")
        return original_respond(self, session, client_id, challenge_name, challenge_responses)

    def confirm_sign_up(self: Any, client_id: str, username: str) -> str:
        raise CodeMismatchException("Invalid verification code provided, please try again.")

    backend_class.respond_to_auth_challenge = respond_to_auth_challenge
    backend_class.confirm_sign_up = confirm_sign_up


def uninstall() -> None:
    if not _ORIGINALS:
        return
    from moto.cognitoidp import models, responses

    models.jwt = _ORIGINALS["jwt"]
    models.jwk = _ORIGINALS["jwk"]
    if _ORIGINALS["pool_key"] is None:
        del models.CognitoIdpUserPool.json_web_key
    else:
        models.CognitoIdpUserPool.json_web_key = _ORIGINALS["pool_key"]
    responses.CognitoIdpJsonWebKeyResponse.json_web_key = _ORIGINALS["jwks"]
    models.CognitoIdpBackend.respond_to_auth_challenge = _ORIGINALS["respond"]
    models.CognitoIdpBackend.confirm_sign_up = _ORIGINALS["confirm"]
    _ORIGINALS.clear()
