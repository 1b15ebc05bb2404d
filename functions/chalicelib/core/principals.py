"""Who is calling: nobody, a signed-in user (Cognito), or a device (car or timer).

Device credentials arrive in a later issue. `verify_device_credential` is the hook they plug into; until then it
rejects every device credential, so `allow={CAR, TIMER}` routes are closed to everyone.
"""
from __future__ import annotations

from collections.abc import Callable
from enum import StrEnum
from typing import Literal

from pydantic import BaseModel, ConfigDict

from chalicelib.core.errors import NotAuthenticated


class Role(StrEnum):
    # Cognito groups (drem_infra.resources.GROUPS)
    ADMIN = "admin"
    OPERATOR = "operator"
    COMMENTATOR = "commentator"
    REGISTRATION = "registration"
    RACER = "racer"
    # Device kinds
    CAR = "car"
    TIMER = "timer"


USER_ROLES = frozenset({Role.ADMIN, Role.OPERATOR, Role.COMMENTATOR, Role.REGISTRATION, Role.RACER})
DEVICE_ROLES = frozenset({Role.CAR, Role.TIMER})


class Anonymous(BaseModel):
    model_config = ConfigDict(frozen=True)
    kind: Literal["anonymous"] = "anonymous"

    @property
    def id(self) -> str:
        return "anonymous"

    @property
    def sub(self) -> str | None:
        return None

    @property
    def roles(self) -> frozenset[Role]:
        return frozenset()

    @property
    def is_user(self) -> bool:
        return False


class User(BaseModel):
    model_config = ConfigDict(frozen=True)
    kind: Literal["user"] = "user"
    sub: str
    username: str
    groups: frozenset[str] = frozenset()

    @property
    def id(self) -> str:
        return f"user:{self.sub}"

    @property
    def roles(self) -> frozenset[Role]:
        # Unknown groups grant nothing: a group name only means something if drem defines it.
        return frozenset(Role(g) for g in self.groups if g in USER_ROLES)

    @property
    def is_user(self) -> bool:
        return True


class RegistryEntry(BaseModel):
    """What the device registry said of a device when its credential was checked, in this request."""
    model_config = ConfigDict(frozen=True)
    hostname: str
    fleet_id: str | None = None


class Device(BaseModel):
    model_config = ConfigDict(frozen=True)
    kind: Literal["device"] = "device"
    device_id: str
    device_kind: Literal["car", "timer"]
    # Set by the credential check (domain.activation): the request's later rules read the registry entry it read
    # moments ago instead of reading the registry again (a timing crossing's way to the board is one read shorter).
    registry: RegistryEntry | None = None

    @property
    def id(self) -> str:
        return f"device:{self.device_id}"

    @property
    def sub(self) -> str | None:
        return None

    @property
    def roles(self) -> frozenset[Role]:
        return frozenset({Role(self.device_kind)})

    @property
    def is_user(self) -> bool:
        return False


Principal = Anonymous | User | Device
ANONYMOUS = Anonymous()

DeviceCredentialVerifier = Callable[[str], Device]


def reject_all_device_credentials(credential: str) -> Device:
    raise NotAuthenticated("Device credentials are not accepted yet.")


_device_verifier: DeviceCredentialVerifier = reject_all_device_credentials


def set_device_credential_verifier(verifier: DeviceCredentialVerifier) -> None:
    """Install the verifier for `Authorization: Device <credential>` (returns a Device or raises NotAuthenticated)."""
    global _device_verifier
    _device_verifier = verifier


def verify_device_credential(credential: str) -> Device:
    return _device_verifier(credential)
