"""Cognito adapter for a signed-in user changing their own password (needs their access token)."""
from __future__ import annotations

from typing import Any

from botocore.exceptions import BotoCoreError, ClientError

from chalicelib.core.errors import InvalidInput
from chalicelib.domain.identity import password_policy_text
from chalicelib.storage.aws_errors import error_code, translate_common

_SERVICE = "The account service"


class CognitoPasswordChanger:
    def __init__(self, client: Any) -> None:
        self._client = client

    def change_password(self, access_token: str, current_password: str, new_password: str) -> None:
        try:
            self._client.change_password(AccessToken=access_token, PreviousPassword=current_password,
                                         ProposedPassword=new_password)
        except ClientError as exc:
            code = error_code(exc)
            if code in ("NotAuthorizedException", "PasswordResetRequiredException"):
                raise InvalidInput("Your current password is not right.", field="current_password") from exc
            if code in ("InvalidPasswordException", "InvalidParameterException"):
                raise InvalidInput(f"This password is too weak. {password_policy_text()}",
                                   field="new_password") from exc
            raise translate_common(exc, _SERVICE) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, _SERVICE) from exc
