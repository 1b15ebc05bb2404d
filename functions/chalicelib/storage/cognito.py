"""Cognito user-pool adapter: sign-in (USER_PASSWORD_AUTH), the NEW_PASSWORD_REQUIRED challenge, refresh, global
sign-out and group look-ups. Takes an injected `cognito-idp` client."""
from __future__ import annotations

from typing import Any

from botocore.exceptions import BotoCoreError, ClientError

from chalicelib.core.errors import (
    AccountNotReady,
    DremError,
    InvalidCredentials,
    InvalidInput,
    NotFound,
    TokenExpired,
)
from chalicelib.domain.identity import NewPasswordChallenge, Tokens, password_policy_text
from chalicelib.storage.aws_errors import error_code, translate_common

_SERVICE = "The sign-in service"


class CognitoIdentityProvider:
    def __init__(self, client: Any, user_pool_id: str, client_id: str) -> None:
        self._client = client
        self._pool_id = user_pool_id
        self._client_id = client_id

    def sign_in(self, username: str, password: str) -> Tokens | NewPasswordChallenge:
        try:
            reply = self._client.initiate_auth(
                AuthFlow="USER_PASSWORD_AUTH", ClientId=self._client_id,
                AuthParameters={"USERNAME": username, "PASSWORD": password})
        except (ClientError, BotoCoreError) as exc:
            raise _sign_in_error(exc) from exc
        if reply.get("ChallengeName") == "NEW_PASSWORD_REQUIRED":
            name = reply.get("ChallengeParameters", {}).get("USERNAME", username)
            return NewPasswordChallenge(username=name, session=reply["Session"])
        if "AuthenticationResult" not in reply:
            raise AccountNotReady(f"Sign-in needs a step drem does not support ({reply.get('ChallengeName')}).",
                                  field="username")
        return _tokens(reply["AuthenticationResult"])

    def complete_new_password(self, challenge: NewPasswordChallenge, new_password: str) -> Tokens:
        try:
            reply = self._client.respond_to_auth_challenge(
                ClientId=self._client_id, ChallengeName="NEW_PASSWORD_REQUIRED", Session=challenge.session,
                ChallengeResponses={"USERNAME": challenge.username, "NEW_PASSWORD": new_password})
        except (ClientError, BotoCoreError) as exc:
            if isinstance(exc, ClientError) and error_code(exc) == "InvalidPasswordException":
                raise InvalidInput(f"This password is too weak. {password_policy_text()}",
                                   field="new_password") from exc
            if isinstance(exc, ClientError) and error_code(exc) in {"NotAuthorizedException", "CodeMismatchException",
                                                                    "ExpiredCodeException"}:
                raise TokenExpired("The sign-in took too long; sign in again with the temporary password.") from exc
            raise _sign_in_error(exc) from exc
        return _tokens(reply["AuthenticationResult"])

    def refresh(self, refresh_token: str) -> Tokens:
        try:
            reply = self._client.initiate_auth(
                AuthFlow="REFRESH_TOKEN_AUTH", ClientId=self._client_id,
                AuthParameters={"REFRESH_TOKEN": refresh_token})
        except ClientError as exc:
            if error_code(exc) == "NotAuthorizedException":
                raise TokenExpired("Your session has ended; sign in again.") from exc
            raise translate_common(exc, _SERVICE) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, _SERVICE) from exc
        result = reply["AuthenticationResult"]
        return _tokens({**result, "RefreshToken": result.get("RefreshToken") or refresh_token})

    def sign_out_everywhere(self, access_token: str) -> None:
        """Revoke the user's refresh tokens. An already invalid token means there is nothing left to revoke."""
        try:
            self._client.global_sign_out(AccessToken=access_token)
        except ClientError as exc:
            if error_code(exc) not in {"NotAuthorizedException", "UserNotFoundException"}:
                raise translate_common(exc, _SERVICE) from exc

    def groups_of(self, username: str) -> list[str]:
        try:
            pages = self._client.get_paginator("admin_list_groups_for_user").paginate(
                UserPoolId=self._pool_id, Username=username)
            return sorted(group["GroupName"] for page in pages for group in page.get("Groups", []))
        except ClientError as exc:
            if error_code(exc) == "UserNotFoundException":
                raise NotFound(f"There is no user {username!r}.", field="username") from exc
            if error_code(exc) == "InvalidParameterException":
                raise InvalidInput(f"{username!r} is not a valid username.", field="username") from exc
            raise translate_common(exc, _SERVICE) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, _SERVICE) from exc


def _tokens(result: dict[str, Any]) -> Tokens:
    return Tokens(access_token=result["AccessToken"], id_token=result["IdToken"],
                  refresh_token=result.get("RefreshToken"), expires_in=int(result.get("ExpiresIn", 3600)))


def _sign_in_error(exc: Exception) -> DremError:
    if isinstance(exc, ClientError):
        code = error_code(exc)
        # Same answer for unknown users and wrong passwords, so the form cannot be used to discover usernames.
        if code in {"NotAuthorizedException", "UserNotFoundException"}:
            return InvalidCredentials("Incorrect username or password.", field="password")
        if code == "UserNotConfirmedException":
            return AccountNotReady("This account is not confirmed yet; ask the event staff.", field="username")
        if code == "PasswordResetRequiredException":
            return AccountNotReady("This account needs a password reset; ask the event staff.", field="username")
        if code == "InvalidParameterException":
            return InvalidInput("Enter a username and password.", field="username")
    return translate_common(exc, _SERVICE)
