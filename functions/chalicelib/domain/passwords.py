"""Changing your own password: the current one proves it is you, the new one must meet the pool policy."""
from __future__ import annotations

from typing import Protocol

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from chalicelib.core.errors import InvalidInput
from chalicelib.domain.users import check_password


class PasswordChangeForm(BaseModel):
    model_config = ConfigDict(extra="forbid")
    current_password: str = Field(min_length=1, max_length=256)
    new_password: str = Field(max_length=256)
    confirm_password: str = Field(max_length=256)

    @field_validator("new_password")
    @classmethod
    def _strong(cls, value: str) -> str:
        return check_password(value, field="new_password")

    @model_validator(mode="after")
    def _same_twice(self) -> PasswordChangeForm:
        if self.new_password != self.confirm_password:
            raise InvalidInput("The two new passwords differ.", field="confirm_password")
        return self


class PasswordChanger(Protocol):
    def change_password(self, access_token: str, current_password: str, new_password: str) -> None: ...


class PasswordService:
    def __init__(self, changer: PasswordChanger) -> None:
        self._changer = changer

    def change(self, access_token: str | None, form: PasswordChangeForm) -> str:
        if not access_token:
            raise InvalidInput("Sign in again, then change your password.", field="current_password")
        self._changer.change_password(access_token, form.current_password, form.new_password)
        return "Your password has been changed."
