"""Cognito adapter for user administration: self sign-up and confirmation, staff-created accounts, listing,
group (role) membership, enabling/disabling and deletion. Takes an injected `cognito-idp` client.

Sign-in lives in `chalicelib.storage.cognito`; this module only reuses a sign-in to check a password."""
from __future__ import annotations

from typing import Any

from botocore.exceptions import BotoCoreError, ClientError

from chalicelib.core.errors import Conflict, DremError, InvalidInput, NotFound
from chalicelib.domain.identity import password_policy_text
from chalicelib.domain.users import DirectoryUser, UserPage
from chalicelib.storage.aws_errors import error_code, is_write, translate_common

_SERVICE = "The account service"
COUNTRY_ATTRIBUTE = "custom:countryCode"


def translate_account_error(exc: Exception, username: str = "", *, write: bool = False) -> DremError:
    """Cognito error codes → what the person filling in the form should do."""
    if isinstance(exc, ClientError):
        code = error_code(exc)
        if code == "UsernameExistsException":
            return Conflict(f"The user name '{username}' is taken.", field="username")
        if code == "UserNotFoundException":
            return NotFound(f"There is no user '{username}'.", field="username")
        if code == "CodeMismatchException":
            return InvalidInput("That confirmation code is wrong; check the latest email and try again.",
                                field="code")
        if code == "ExpiredCodeException":
            return InvalidInput("That confirmation code has expired; ask for a new one.", field="code")
        if code == "InvalidPasswordException":
            return InvalidInput(f"This password is too weak. {password_policy_text()}", field="password")
        if code == "InvalidParameterException":
            return InvalidInput("Cognito rejected one of the values; check the username, email and country.")
    return translate_common(exc, _SERVICE, write=write)


class CognitoUserDirectory:
    def __init__(self, client: Any, user_pool_id: str, client_id: str) -> None:
        self._client = client
        self._pool_id = user_pool_id
        self._client_id = client_id

    def sign_up(self, username: str, password: str, email: str, country_code: str) -> str:
        reply = self._call(username, "sign_up", ClientId=self._client_id, Username=username, Password=password,
                           UserAttributes=_attributes(email, country_code))
        return reply["UserSub"]

    def confirm_sign_up(self, username: str, code: str) -> None:
        try:
            self._client.confirm_sign_up(ClientId=self._client_id, Username=username, ConfirmationCode=code)
        except ClientError as exc:
            if error_code(exc) == "NotAuthorizedException":
                raise InvalidInput("This account is already confirmed or cannot be confirmed; try signing in.",
                                   field="username") from exc
            raise translate_account_error(exc, username) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, _SERVICE) from exc

    def confirm_without_code(self, username: str) -> None:
        self._call(username, "admin_confirm_sign_up", UserPoolId=self._pool_id, Username=username)

    def create_user(self, username: str, email: str, country_code: str, temporary_password: str) -> str:
        # SUPPRESS: drem shows the temporary password to the staff member once; there is no mail server locally.
        reply = self._call(username, "admin_create_user", UserPoolId=self._pool_id, Username=username,
                           TemporaryPassword=temporary_password, MessageAction="SUPPRESS",
                           UserAttributes=[*_attributes(email, country_code),
                                           {"Name": "email_verified", "Value": "true"}])
        return _user(reply["User"]).sub

    def reset_temporary_password(self, username: str, temporary_password: str) -> None:
        """A new temporary password for an account that never signed in (the old one stops working)."""
        self._call(username, "admin_set_user_password", UserPoolId=self._pool_id, Username=username,
                   Password=temporary_password, Permanent=False)

    def get_user(self, username: str) -> DirectoryUser:
        reply = self._call(username, "admin_get_user", UserPoolId=self._pool_id, Username=username)
        return _user({**reply, "Attributes": reply.get("UserAttributes", [])})

    def list_users(self, prefix: str | None, limit: int, next_token: str | None) -> UserPage:
        request: dict[str, Any] = {"UserPoolId": self._pool_id, "Limit": limit}
        if prefix:
            request["Filter"] = f'username ^= "{prefix}"'
        if next_token:
            request["PaginationToken"] = next_token
        try:
            reply = self._client.list_users(**request)
        except ClientError as exc:
            # A token Cognito did not issue (or one that expired): the caller's mistake, not Cognito failing.
            if next_token and error_code(exc) in {"InvalidParameterException", "InvalidToken"}:
                raise InvalidInput("This page token is not valid here; start again from the first page.",
                                   field="next") from exc
            raise translate_account_error(exc) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, _SERVICE) from exc
        return UserPage(users=[_user(u) for u in reply.get("Users", [])], next_token=reply.get("PaginationToken"))

    def groups_of(self, username: str) -> list[str]:
        pages = self._paginate(username, "admin_list_groups_for_user", UserPoolId=self._pool_id, Username=username)
        return sorted(group["GroupName"] for page in pages for group in page.get("Groups", []))

    def members_of(self, group: str) -> set[str]:
        pages = self._paginate("", "list_users_in_group", UserPoolId=self._pool_id, GroupName=group)
        return {user["Username"] for page in pages for user in page.get("Users", [])}

    def set_only_group(self, username: str, group: str) -> None:
        """Add the new group before removing the others, so the user is never left with no role."""
        current = self.groups_of(username)
        if group not in current:
            self._call(username, "admin_add_user_to_group", UserPoolId=self._pool_id, Username=username,
                       GroupName=group)
        for other in current:
            if other != group:
                self._call(username, "admin_remove_user_from_group", UserPoolId=self._pool_id,
                           Username=username, GroupName=other)

    def set_enabled(self, username: str, enabled: bool) -> None:
        operation = "admin_enable_user" if enabled else "admin_disable_user"
        self._call(username, operation, UserPoolId=self._pool_id, Username=username)
        if not enabled:
            # Refresh tokens stop working at once; access tokens already issued run out within the hour.
            self._call(username, "admin_user_global_sign_out", UserPoolId=self._pool_id, Username=username)

    def delete_user(self, username: str) -> None:
        try:
            self._client.admin_delete_user(UserPoolId=self._pool_id, Username=username)
        except ClientError as exc:
            if error_code(exc) != "UserNotFoundException":  # already gone: a retried deletion succeeded earlier
                raise translate_account_error(exc, username) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, _SERVICE) from exc

    def password_matches(self, username: str, password: str) -> bool:
        try:
            reply = self._client.initiate_auth(AuthFlow="USER_PASSWORD_AUTH", ClientId=self._client_id,
                                               AuthParameters={"USERNAME": username, "PASSWORD": password})
        except ClientError as exc:
            if error_code(exc) in {"NotAuthorizedException", "UserNotFoundException", "InvalidParameterException"}:
                return False
            raise translate_common(exc, _SERVICE) from exc
        except BotoCoreError as exc:
            raise translate_common(exc, _SERVICE) from exc
        return "AuthenticationResult" in reply or "ChallengeName" in reply

    def _call(self, username: str, operation: str, **kwargs: Any) -> dict[str, Any]:
        try:
            return getattr(self._client, operation)(**kwargs)
        except (ClientError, BotoCoreError) as exc:
            raise translate_account_error(exc, username, write=is_write(operation)) from exc

    def _paginate(self, username: str, operation: str, **kwargs: Any) -> list[dict[str, Any]]:
        try:
            return list(self._client.get_paginator(operation).paginate(**kwargs))
        except (ClientError, BotoCoreError) as exc:
            raise translate_account_error(exc, username) from exc


def _attributes(email: str, country_code: str) -> list[dict[str, str]]:
    return [{"Name": "email", "Value": email}, {"Name": COUNTRY_ATTRIBUTE, "Value": country_code}]


def _user(raw: dict[str, Any]) -> DirectoryUser:
    attributes = {a["Name"]: a.get("Value", "") for a in raw.get("Attributes", [])}
    created = raw.get("UserCreateDate")
    return DirectoryUser(username=raw["Username"], sub=attributes.get("sub", ""), email=attributes.get("email"),
                         country_code=attributes.get(COUNTRY_ATTRIBUTE), enabled=raw.get("Enabled", True),
                         status=raw.get("UserStatus", "UNKNOWN"),
                         created_at=created.isoformat() if hasattr(created, "isoformat") else None)
