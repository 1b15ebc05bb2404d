"""Devices (cars and timers): their status board, heartbeats, the commands staff queue for them, and staff actions.

Status: every device has an entry in one materialised status item, so "which cars are online" is a single read.
A heartbeat stamps `last_seen_ms` (and what the device reports) into that entry; "online" is derived when the board is
read: seen within `ONLINE_WINDOW_MS`. Commands are queued per device; the device fetches its pending ones, carries them
out and acknowledges each with ok|failed. A device only ever reaches its own queue: the device id comes from its
verified credential, never from the URL.
"""
from __future__ import annotations

import re
import secrets
from collections.abc import Callable
from enum import StrEnum
from typing import Any, Literal, Protocol

from pydantic import BaseModel, ConfigDict, Field, computed_field, field_validator, model_validator

from chalicelib.core.errors import InvalidInput, NotFound
from chalicelib.core.principals import Device, User

ONLINE_WINDOW_MS = 15_000
HOSTNAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9-]{0,62}$"

# DREM's tail-light presets (carSetTaillightColor); anything else must be #RRGGBB.
TAIL_LIGHT_PALETTE: dict[str, str] = {
    "blue": "#0000FF", "red": "#FF0000", "marigold": "#FFA500", "orchid purple": "#DA70D6",
    "sky blue": "#87CEEB", "green": "#00FF00", "violet": "#8F00FF", "lime": "#BFFF00",
}
_HEX_COLOUR = re.compile(r"^#[0-9A-Fa-f]{6}$")


class DeviceKind(StrEnum):
    CAR = "car"
    TIMER = "timer"


class CarVideoSettings(BaseModel):
    """How a car's camera goes to the stream (issue #35): staff choose it on the Cars page, the live server hands it to
    the car with every answer to its relay (drem_cars.video_relay), and the car sends at it from then on. `model`: what
    the model sees, 160×120 grey, whatever the size. A car without settings sends at its own (`drem car run` flags)."""
    model_config = ConfigDict(frozen=True, extra="forbid")

    fps: int = Field(default=15, ge=1, le=30, description="frames a second, 1 to 30")
    width: int = Field(default=480, ge=160, le=1280)
    height: int = Field(default=360, ge=120, le=720)
    view: Literal["camera", "model"] = "camera"

    @model_validator(mode="before")
    @classmethod
    def _size_as_text(cls, data: Any) -> Any:
        """A form sends the size as one field, `480x360`."""
        if isinstance(data, dict) and "size" in data:
            data = dict(data)
            width, _, height = str(data.pop("size")).lower().partition("x")
            if not (width.isdigit() and height.isdigit()):
                raise ValueError("Give the size as WIDTHxHEIGHT, e.g. 480x360.")
            data.update(width=int(width), height=int(height))
        return data


class DeviceRecord(BaseModel):
    """The registry item of one device, including the SHA-256 of its current secret (never the secret)."""
    model_config = ConfigDict(frozen=True)

    device_id: str
    kind: DeviceKind
    hostname: str
    fleet_id: str | None = None
    secret_hash: str
    registered_at_ms: int
    activated_by: str = ""
    video: CarVideoSettings | None = None  # a car's camera settings, once staff chose them


class LoadedModel(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(min_length=1, max_length=200)
    md5: str = Field(pattern=r"^[0-9a-f]{32}$")


class Telemetry(BaseModel):
    """What a device reports with each heartbeat; every field optional (a timer has no battery or model)."""
    model_config = ConfigDict(frozen=True, extra="forbid")

    agent_version: str | None = Field(default=None, max_length=64)
    model: LoadedModel | None = None
    battery_pct: float | None = Field(default=None, ge=0, le=100)
    # Small on purpose: every device's line lives in one status item (DynamoDB items are at most 400 KB).
    faults: list[str] = Field(default_factory=list, max_length=10)
    inference_latency_ms: float | None = Field(default=None, ge=0, le=60_000)
    fps: float | None = Field(default=None, ge=0, le=1000)
    times_laps: bool = Field(default=False, description="the device posts strip events itself (a sim car's "
                                                        "timing line): the timekeeper counts it as the track's timer")

    @field_validator("faults")
    @classmethod
    def _short_faults(cls, faults: list[str]) -> list[str]:
        if any(len(f) > 120 for f in faults):
            raise ValueError("each fault is at most 120 characters")
        return faults


class StatusEntry(BaseModel):
    """One device's line on the status board (stored; `online` is derived on read)."""
    model_config = ConfigDict(frozen=True)

    device_id: str
    kind: DeviceKind
    hostname: str
    fleet_id: str | None = None
    registered_at_ms: int
    last_seen_ms: int | None = None
    telemetry: Telemetry | None = None
    video: CarVideoSettings | None = None

    @classmethod
    def for_device(cls, device: DeviceRecord) -> StatusEntry:
        return cls(device_id=device.device_id, kind=device.kind, hostname=device.hostname, fleet_id=device.fleet_id,
                   registered_at_ms=device.registered_at_ms, video=device.video)


class DeviceView(StatusEntry):
    now_ms: int = Field(exclude=True)

    @computed_field  # type: ignore[prop-decorator]
    @property
    def online(self) -> bool:
        return self.last_seen_ms is not None and self.now_ms - self.last_seen_ms <= ONLINE_WINDOW_MS

    @computed_field  # type: ignore[prop-decorator]
    @property
    def seconds_since_seen(self) -> float | None:
        return None if self.last_seen_ms is None else round(max(0, self.now_ms - self.last_seen_ms) / 1000, 1)


class CommandType(StrEnum):
    RESTART_SERVICE = "RESTART_SERVICE"
    EMERGENCY_STOP = "EMERGENCY_STOP"
    START_CAR = "START_CAR"  # a stock DeepRacer stays stopped after loading a model until staff start it
    SET_TAIL_LIGHT = "SET_TAIL_LIGHT"
    DELETE_ALL_MODELS = "DELETE_ALL_MODELS"
    SET_THROTTLE_CAP = "SET_THROTTLE_CAP"


CAR_ONLY_COMMANDS = frozenset(set(CommandType) - {CommandType.RESTART_SERVICE})


class CommandRequest(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    type: CommandType
    colour: str | None = Field(default=None, description="SET_TAIL_LIGHT: a palette name or #RRGGBB")
    throttle_cap_pct: int | None = Field(default=None, ge=0, le=100)
    with_system_logs: bool = Field(default=False, description="DELETE_ALL_MODELS: also clear the car's logs")

    @model_validator(mode="after")
    def _parameters_fit_type(self) -> CommandRequest:
        if self.type is CommandType.SET_TAIL_LIGHT:
            if self.colour is None:
                raise ValueError("SET_TAIL_LIGHT needs colour (a palette name or #RRGGBB)")
            colour = self.colour.strip()
            if colour.lower() not in TAIL_LIGHT_PALETTE and not _HEX_COLOUR.match(colour):
                raise ValueError(f"colour must be #RRGGBB or one of: {', '.join(TAIL_LIGHT_PALETTE)}")
        elif self.colour is not None:
            raise ValueError("colour only applies to SET_TAIL_LIGHT")
        if self.type is CommandType.SET_THROTTLE_CAP and self.throttle_cap_pct is None:
            raise ValueError("SET_THROTTLE_CAP needs throttle_cap_pct (0-100)")
        if self.type is not CommandType.SET_THROTTLE_CAP and self.throttle_cap_pct is not None:
            raise ValueError("throttle_cap_pct only applies to SET_THROTTLE_CAP")
        return self

    def parameters(self) -> dict[str, object]:
        if self.type is CommandType.SET_TAIL_LIGHT and self.colour is not None:
            colour = self.colour.strip()
            return {"colour": TAIL_LIGHT_PALETTE.get(colour.lower(), colour.upper())}
        if self.type is CommandType.SET_THROTTLE_CAP:
            return {"throttle_cap_pct": self.throttle_cap_pct}
        if self.type is CommandType.DELETE_ALL_MODELS:
            return {"with_system_logs": self.with_system_logs}
        return {}


class CommandStatus(StrEnum):
    PENDING = "pending"
    OK = "ok"
    FAILED = "failed"


class Command(BaseModel):
    model_config = ConfigDict(frozen=True)

    command_id: str = Field(description="'{created ms, 13 digits}-{random}': sorts by time")
    device_id: str
    type: CommandType
    parameters: dict[str, object] = Field(default_factory=dict)
    status: CommandStatus = CommandStatus.PENDING
    message: str = ""
    created_at_ms: int
    created_by: str
    acked_at_ms: int | None = None


class CommandAck(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    result: CommandStatus
    message: str = Field(default="", max_length=1000)

    @field_validator("result")
    @classmethod
    def _final(cls, value: CommandStatus) -> CommandStatus:
        if value is CommandStatus.PENDING:
            raise ValueError("result is ok or failed")
        return value


class MoveToFleet(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    fleet_id: str | None = Field(description="null leaves the device in no fleet")


COMMAND_ID_PATTERN = re.compile(r"^\d{13}-[0-9a-f]{8}$")


class DeviceRepository(Protocol):
    def get_device(self, device_id: str) -> DeviceRecord | None: ...
    def delete_device(self, device_id: str) -> None: ...
    def set_fleet(self, device_id: str, fleet_id: str | None) -> None: ...
    def set_video(self, device_id: str, video: CarVideoSettings) -> None: ...
    def status_board(self) -> dict[str, StatusEntry]: ...
    def put_status_entry(self, entry: StatusEntry) -> None: ...
    def record_heartbeat(self, device_id: str, now_ms: int, telemetry: Telemetry) -> bool: ...
    def put_command(self, command: Command) -> None: ...
    def commands(self, device_id: str, *, pending_only: bool = False) -> list[Command]: ...
    def ack_command(self, device_id: str, command_id: str, ack: CommandAck, now_ms: int) -> Command | None: ...


class FleetLookup(Protocol):
    def fleet_exists(self, fleet_id: str) -> bool: ...


class DeviceService:
    def __init__(self, devices: DeviceRepository, fleets: FleetLookup, clock_ms: Callable[[], int]) -> None:
        self._devices = devices
        self._fleets = fleets
        self._clock_ms = clock_ms

    # --- staff ---
    def list_devices(self, *, online: bool | None = None, fleet_id: str | None = None) -> list[DeviceView]:
        now = self._clock_ms()
        views = [DeviceView(**entry.model_dump(), now_ms=now) for entry in self._devices.status_board().values()]
        views = [v for v in views if (online is None or v.online == online)
                 and (fleet_id is None or v.fleet_id == fleet_id)]
        return sorted(views, key=lambda v: (v.kind, v.hostname, v.device_id))

    def get_device(self, device_id: str) -> DeviceView:
        entry = self._devices.status_board().get(device_id)
        device = self._devices.get_device(device_id)
        if device is None:
            raise NotFound(f"There is no device {device_id}.")
        entry = entry or StatusEntry.for_device(device)
        return DeviceView(**entry.model_dump(), now_ms=self._clock_ms())

    def move_to_fleet(self, device_id: str, fleet_id: str | None) -> DeviceView:
        if fleet_id is not None and not self._fleets.fleet_exists(fleet_id):
            raise InvalidInput(f"There is no fleet {fleet_id}.", field="fleet_id")
        if self._devices.get_device(device_id) is None:
            raise NotFound(f"There is no device {device_id}.")
        self._devices.set_fleet(device_id, fleet_id)
        return self.get_device(device_id)

    def set_video(self, device_id: str, video: CarVideoSettings) -> CarVideoSettings:
        """The car's camera relay sends at these settings from its next answer from the live server on (at most the
        live server's credential cache, 10 s, later)."""
        device = self._devices.get_device(device_id)
        if device is None:
            raise NotFound(f"There is no device {device_id}.")
        if device.kind != DeviceKind.CAR:
            raise InvalidInput(f"{device.hostname} is a timer: only cars have a camera.", field="view")
        self._devices.set_video(device_id, video)
        return video

    def set_fleet_video(self, fleet_id: str, video: CarVideoSettings) -> list[str]:
        """The same camera settings for every car of a fleet (the ids of those cars; a fleet of timers has none)."""
        if not self._fleets.fleet_exists(fleet_id):
            raise NotFound(f"There is no fleet {fleet_id}.")
        cars = [v.device_id for v in self.list_devices(fleet_id=fleet_id) if v.kind is DeviceKind.CAR]
        for device_id in cars:
            self._devices.set_video(device_id, video)
        return cars

    def deregister(self, device_id: str) -> None:
        """The device's credential stops working with the next request: the verifier reads the registry each time."""
        if self._devices.get_device(device_id) is None:
            raise NotFound(f"There is no device {device_id}.")
        self._devices.delete_device(device_id)

    def queue_command(self, principal: User, device_id: str, request: CommandRequest) -> Command:
        device = self._devices.get_device(device_id)
        if device is None:
            raise NotFound(f"There is no device {device_id}.")
        if device.kind is DeviceKind.TIMER and request.type in CAR_ONLY_COMMANDS:
            raise InvalidInput(f"{request.type.value} is for cars; {device.hostname} is a timer.", field="type")
        now = self._clock_ms()
        command = Command(command_id=f"{now:013d}-{secrets.token_hex(4)}", device_id=device_id, type=request.type,
                          parameters=request.parameters(), created_at_ms=now, created_by=principal.username)
        self._devices.put_command(command)
        return command

    def device_commands(self, device_id: str) -> list[Command]:
        if self._devices.get_device(device_id) is None:
            raise NotFound(f"There is no device {device_id}.")
        return self._devices.commands(device_id)

    # --- the device itself ---
    def heartbeat(self, device: Device, telemetry: Telemetry) -> DeviceView:
        now = self._clock_ms()
        if not self._devices.record_heartbeat(device.device_id, now, telemetry):
            # No status line yet (e.g. the board was rebuilt): write a full one from the registry.
            record = self._devices.get_device(device.device_id)
            if record is None:
                raise NotFound("This device is no longer registered.")
            self._devices.put_status_entry(StatusEntry.for_device(record).model_copy(
                update={"last_seen_ms": now, "telemetry": telemetry}))
        return self.get_device(device.device_id)

    def pending_commands(self, device: Device) -> list[Command]:
        return self._devices.commands(device.device_id, pending_only=True)

    def acknowledge(self, device: Device, command_id: str, ack: CommandAck) -> Command:
        if not COMMAND_ID_PATTERN.match(command_id):
            raise NotFound(f"There is no command {command_id} for this device.")
        # Keyed by the caller's own device id: another device's command id simply is not found.
        command = self._devices.ack_command(device.device_id, command_id, ack, self._clock_ms())
        if command is None:
            raise NotFound(f"There is no pending command {command_id} for this device.")
        return command
