"""Sign-in results and forms, as the identity provider adapter returns and the login pages consume them."""
from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, model_validator

from drem_infra import resources


class Tokens(BaseModel):
    model_config = ConfigDict(frozen=True)

    access_token: str
    id_token: str
    # A refresh grant does not return a new refresh token; the old one stays valid.
    refresh_token: str | None = None
    expires_in: int = 3600


class NewPasswordChallenge(BaseModel):
    """Cognito wants a permanent password before it issues tokens (users created with a temporary one)."""
    model_config = ConfigDict(frozen=True)

    username: str
    session: str


class SignInForm(BaseModel):
    username: str = Field(min_length=1, max_length=128)
    password: str = Field(min_length=1, max_length=256)

    @model_validator(mode="before")
    @classmethod
    def _strip_username(cls, data: Any) -> Any:
        if isinstance(data, dict) and isinstance(data.get("username"), str):
            data = {**data, "username": data["username"].strip()}
        return data


class NewPasswordForm(BaseModel):
    new_password: str = Field(min_length=1, max_length=256)
    confirm_password: str = Field(min_length=1, max_length=256)


def password_policy_text() -> str:
    policy = resources.USER_POOL.password_policy
    needs = [label for label, required in (
        ("a lower-case letter", policy.require_lowercase),
        ("an upper-case letter", policy.require_uppercase),
        ("a digit", policy.require_digits),
        ("a symbol", policy.require_symbols),
    ) if required]
    return f"At least {policy.minimum_length} characters, with " + ", ".join(needs) + "."
