"""Bringing a car or timer into drem, and its credential from then on.

1. An operator asks for a one-time activation code, bound to a fleet, a hostname and a device kind (car|timer). Only
   the code's SHA-256 is stored; the code itself is shown once. It expires (default 1 h).
2. The device sends the code with its hostname and kind to `POST /api/devices/activate` (the only unauthenticated
   device endpoint). Redeeming marks the code used, registers the device and puts its line on the status board in one
   conditional transaction, so a code works exactly once even when two devices race for it, and a crash leaves
   either nothing or all three.
   The answer can still be lost (the app dies after the commit, the WiFi drops): the device then retries with the
   same `attempt_id`, a random value it drew for this activation. Until the code expires and while the device has
   never been heard from, that retry resumes the activation: the same device id with a fresh secret (only hashes are
   stored, so the first secret cannot be shown again; it was never delivered, so nothing holds it). Anyone else
   with the code but not the attempt id gets "already used".
3. The device gets `<device_id>.<secret>` and sends it as `Authorization: Device <device_id>.<secret>`. drem keeps
   only the secret's SHA-256 and compares in constant time. Rotation replaces the hash and deregistration deletes the
   device; both take effect on the next request because every request reads the registry item.
"""
from __future__ import annotations

import base64
import hashlib
import hmac
import secrets
import uuid
from collections.abc import Callable
from typing import Protocol

from pydantic import BaseModel, ConfigDict, Field, field_validator

from chalicelib.core.errors import InvalidInput, NotAuthenticated
from chalicelib.core.principals import Device, RegistryEntry, User
from chalicelib.domain.devices import HOSTNAME_PATTERN, DeviceKind, DeviceRecord, StatusEntry

DEFAULT_CODE_TTL_MINUTES = 60
MAX_CODE_TTL_MINUTES = 24 * 60


class ActivationCodeRequest(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    fleet_id: str = Field(min_length=1, max_length=64)
    hostname: str = Field(pattern=HOSTNAME_PATTERN)
    device_kind: DeviceKind
    ttl_minutes: int = Field(default=DEFAULT_CODE_TTL_MINUTES, ge=1, le=MAX_CODE_TTL_MINUTES)


class ActivationRecord(BaseModel):
    """A stored activation code (by hash)."""
    model_config = ConfigDict(frozen=True)

    code_hash: str
    fleet_id: str
    hostname: str
    device_kind: DeviceKind
    expires_at_ms: int
    created_at_ms: int
    created_by: str
    # Set when redeemed: the device it registered, and the SHA-256 of the attempt id that redeemed it (if sent).
    redeemed_device_id: str | None = None
    redeemed_attempt_hash: str | None = None


class IssuedActivationCode(BaseModel):
    model_config = ConfigDict(frozen=True)

    code: str = Field(description="shown once; drem keeps only its SHA-256")
    fleet_id: str
    hostname: str
    device_kind: DeviceKind
    expires_at_ms: int


class ActivationExchange(BaseModel):
    """What the device sends to activate itself."""
    model_config = ConfigDict(frozen=True, extra="forbid")

    code: str = Field(min_length=1, max_length=100)
    hostname: str = Field(pattern=HOSTNAME_PATTERN)
    device_kind: DeviceKind
    attempt_id: str | None = Field(
        default=None, min_length=16, max_length=64, pattern=r"^[A-Za-z0-9_-]+$",
        description="a random value the device draws once per activation; a retry with it resumes an activation "
                    "whose answer was lost")

    @field_validator("code")
    @classmethod
    def _normalised(cls, value: str) -> str:
        return normalise_code(value)


class IssuedCredential(BaseModel):
    model_config = ConfigDict(frozen=True)

    device_id: str
    device_kind: DeviceKind
    hostname: str
    fleet_id: str | None
    credential: str = Field(description="send as 'Authorization: Device <credential>'; shown once")


class ActivationRepository(Protocol):
    def put_activation(self, record: ActivationRecord) -> None: ...
    def get_activation(self, code_hash: str) -> ActivationRecord | None: ...
    def redeem(self, code_hash: str, exchange: ActivationExchange, now_ms: int, device: DeviceRecord,
               line: StatusEntry, attempt_hash: str | None) -> bool: ...
    def get_device(self, device_id: str) -> DeviceRecord | None: ...
    def status_board(self) -> dict[str, StatusEntry]: ...
    def replace_secret_hash(self, device_id: str, secret_hash: str) -> bool: ...
    def put_status_entry(self, entry: StatusEntry) -> None: ...


class FleetLookup(Protocol):
    def fleet_exists(self, fleet_id: str) -> bool: ...


def sha256_hex(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def normalise_code(code: str) -> str:
    """Codes are typed by people: ignore case, spaces and dashes."""
    return "".join(ch for ch in code.upper() if ch.isalnum())


def new_code() -> str:
    # 100 bits of base32, shown as five groups of four: easy to read out and type on a car's console.
    raw = base64.b32encode(secrets.token_bytes(15)).decode().rstrip("=")[:20]
    return "-".join(raw[i:i + 4] for i in range(0, 20, 4))


def new_secret() -> str:
    return secrets.token_urlsafe(32)


def parse_credential(credential: str) -> tuple[str, str]:
    device_id, dot, secret = credential.strip().partition(".")
    if not dot or not device_id or not secret:
        raise NotAuthenticated("Use 'Authorization: Device <device_id>.<secret>'.")
    return device_id, secret


class ActivationService:
    def __init__(self, store: ActivationRepository, fleets: FleetLookup, clock_ms: Callable[[], int]) -> None:
        self._store = store
        self._fleets = fleets
        self._clock_ms = clock_ms

    def issue_code(self, principal: User, request: ActivationCodeRequest) -> IssuedActivationCode:
        if not self._fleets.fleet_exists(request.fleet_id):
            raise InvalidInput(f"There is no fleet {request.fleet_id}.", field="fleet_id")
        code, now = new_code(), self._clock_ms()
        record = ActivationRecord(code_hash=sha256_hex(normalise_code(code)), fleet_id=request.fleet_id,
                                  hostname=request.hostname, device_kind=request.device_kind,
                                  expires_at_ms=now + request.ttl_minutes * 60_000, created_at_ms=now,
                                  created_by=principal.username)
        self._store.put_activation(record)
        return IssuedActivationCode(code=code, fleet_id=record.fleet_id, hostname=record.hostname,
                                    device_kind=record.device_kind, expires_at_ms=record.expires_at_ms)

    def activate(self, exchange: ActivationExchange) -> IssuedCredential:
        code_hash, now, secret = sha256_hex(exchange.code), self._clock_ms(), new_secret()
        stored = self._store.get_activation(code_hash)
        if stored is None:
            raise InvalidInput("This activation code is unknown or has already been used.", field="code")
        _check_binding(stored, exchange, now)
        if stored.redeemed_device_id is not None:
            return self._resume(stored, exchange)
        device = DeviceRecord(device_id=f"{exchange.device_kind.value}-{uuid.uuid4().hex[:12]}",
                              kind=exchange.device_kind, hostname=exchange.hostname, fleet_id=stored.fleet_id,
                              secret_hash=sha256_hex(secret), registered_at_ms=now, activated_by=stored.created_by)
        attempt_hash = sha256_hex(exchange.attempt_id) if exchange.attempt_id else None
        # The check above explains a refusal; this conditional transaction is what makes the code single-use.
        if not self._store.redeem(code_hash, exchange, now, device, StatusEntry.for_device(device), attempt_hash):
            raise InvalidInput("This activation code is unknown or has already been used.", field="code")
        return IssuedCredential(device_id=device.device_id, device_kind=device.kind, hostname=device.hostname,
                                fleet_id=device.fleet_id, credential=f"{device.device_id}.{secret}")

    def _resume(self, stored: ActivationRecord, exchange: ActivationExchange) -> IssuedCredential:
        """A retry of an activation whose answer was lost: a fresh secret for the device it registered."""
        used = InvalidInput("This activation code has already been used. If this device never got its credential, "
                            "ask an operator for a new code.", field="code")
        if (exchange.attempt_id is None or stored.redeemed_attempt_hash is None
                or not hmac.compare_digest(sha256_hex(exchange.attempt_id), stored.redeemed_attempt_hash)):
            raise used
        device_id = stored.redeemed_device_id or ""
        device, line = self._store.get_device(device_id), self._store.status_board().get(device_id)
        if device is None or (line is not None and line.last_seen_ms is not None):
            raise used  # deregistered since, or it has already used its credential: the answer did arrive
        secret = new_secret()
        if not self._store.replace_secret_hash(device_id, sha256_hex(secret)):
            raise used
        if line is None:
            self._store.put_status_entry(StatusEntry.for_device(device))
        return IssuedCredential(device_id=device.device_id, device_kind=device.kind, hostname=device.hostname,
                                fleet_id=device.fleet_id, credential=f"{device.device_id}.{secret}")

    def rotate(self, device: Device) -> IssuedCredential:
        record = self._store.get_device(device.device_id)
        secret = new_secret()
        if record is None or not self._store.replace_secret_hash(device.device_id, sha256_hex(secret)):
            raise NotAuthenticated("This device is no longer registered.")
        return IssuedCredential(device_id=record.device_id, device_kind=record.kind, hostname=record.hostname,
                                fleet_id=record.fleet_id, credential=f"{record.device_id}.{secret}")

    def verify(self, credential: str) -> Device:
        device_id, secret = parse_credential(credential)
        record = self._store.get_device(device_id) if len(device_id) <= 64 else None
        # Hash even when the device is unknown, so a miss takes as long as a wrong secret.
        presented = sha256_hex(secret)
        expected = record.secret_hash if record else sha256_hex(new_secret())
        if record is None or not hmac.compare_digest(presented, expected):
            raise NotAuthenticated("This device credential is not valid (wrong, rotated or deregistered).")
        return Device(device_id=record.device_id, device_kind=record.kind.value,
                      registry=RegistryEntry(hostname=record.hostname, fleet_id=record.fleet_id))


def _check_binding(stored: ActivationRecord, exchange: ActivationExchange, now_ms: int) -> None:
    if stored.expires_at_ms <= now_ms:
        raise InvalidInput("This activation code has expired; ask an operator for a new one.", field="code")
    if stored.device_kind is not exchange.device_kind:
        raise InvalidInput(f"This activation code is for a {stored.device_kind.value}, not a "
                           f"{exchange.device_kind.value}.", field="device_kind")
    if stored.hostname.lower() != exchange.hostname.lower():
        raise InvalidInput(f"This activation code is for the host {stored.hostname!r}.", field="hostname")
