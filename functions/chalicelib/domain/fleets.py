"""Fleets: named groups of devices (a track's cars, the timers of a venue).

A device's fleet is stored once, on the device (registry item and status-board line); a fleet's member list is
derived from the status board when read, so moving a car can never leave it listed in two fleets.
"""
from __future__ import annotations

import uuid
from collections.abc import Callable
from typing import Protocol

from pydantic import BaseModel, ConfigDict, Field, field_validator

from chalicelib.core.errors import InvalidInput, NotFound
from chalicelib.core.principals import User
from chalicelib.domain.devices import StatusEntry


class FleetInput(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(min_length=1, max_length=80)
    device_ids: list[str] | None = Field(
        default=None, max_length=500,
        description="create: devices to move into the new fleet; update: the full member list (None = unchanged)")

    @field_validator("name")
    @classmethod
    def _trimmed(cls, value: str) -> str:
        if not value.strip():
            raise ValueError("name must not be blank")
        return value.strip()


class FleetRecord(BaseModel):
    model_config = ConfigDict(frozen=True)

    fleet_id: str
    name: str
    created_at_ms: int
    created_by: str


class Fleet(FleetRecord):
    device_ids: list[str] = Field(default_factory=list)


class FleetRepository(Protocol):
    def get_fleet(self, fleet_id: str) -> FleetRecord | None: ...
    def list_fleets(self) -> list[FleetRecord]: ...
    def put_fleet(self, fleet: FleetRecord) -> None: ...
    def delete_fleet(self, fleet_id: str) -> None: ...


class DeviceMembership(Protocol):
    def status_board(self) -> dict[str, StatusEntry]: ...
    def set_fleet(self, device_id: str, fleet_id: str | None) -> None: ...


class FleetService:
    def __init__(self, fleets: FleetRepository, devices: DeviceMembership, clock_ms: Callable[[], int]) -> None:
        self._fleets = fleets
        self._devices = devices
        self._clock_ms = clock_ms

    def list_fleets(self) -> list[Fleet]:
        members = self._members()
        fleets = [Fleet(**f.model_dump(), device_ids=members.get(f.fleet_id, [])) for f in self._fleets.list_fleets()]
        return sorted(fleets, key=lambda f: f.name.lower())

    def get_fleet(self, fleet_id: str) -> Fleet:
        record = self._record(fleet_id)
        return Fleet(**record.model_dump(), device_ids=self._members().get(fleet_id, []))

    def create_fleet(self, principal: User, data: FleetInput) -> Fleet:
        board = self._devices.status_board()
        self._check_devices(data.device_ids or [], board)
        record = FleetRecord(fleet_id=uuid.uuid4().hex[:12], name=data.name, created_at_ms=self._clock_ms(),
                             created_by=principal.username)
        self._fleets.put_fleet(record)
        for device_id in data.device_ids or []:
            self._devices.set_fleet(device_id, record.fleet_id)
        return self.get_fleet(record.fleet_id)

    def update_fleet(self, principal: User, fleet_id: str, data: FleetInput) -> Fleet:
        record = self._record(fleet_id)
        board = self._devices.status_board()
        self._check_devices(data.device_ids or [], board)  # before any write: a refused edit changes nothing
        self._fleets.put_fleet(record.model_copy(update={"name": data.name}))
        if data.device_ids is not None:
            wanted = set(data.device_ids)
            for device_id, entry in board.items():
                if entry.fleet_id == fleet_id and device_id not in wanted:
                    self._devices.set_fleet(device_id, None)
            for device_id in data.device_ids:
                if board[device_id].fleet_id != fleet_id:
                    self._devices.set_fleet(device_id, fleet_id)
        return self.get_fleet(fleet_id)

    def delete_fleet(self, principal: User, fleet_id: str) -> None:
        """The fleet's devices stay registered, in no fleet, until someone moves them (nothing is lost)."""
        self._record(fleet_id)
        for device_id in self._members().get(fleet_id, []):
            self._devices.set_fleet(device_id, None)
        self._fleets.delete_fleet(fleet_id)

    def _record(self, fleet_id: str) -> FleetRecord:
        record = self._fleets.get_fleet(fleet_id)
        if record is None:
            raise NotFound(f"There is no fleet {fleet_id}.")
        return record

    def _members(self) -> dict[str, list[str]]:
        members: dict[str, list[str]] = {}
        for device_id, entry in sorted(self._devices.status_board().items()):
            if entry.fleet_id:
                members.setdefault(entry.fleet_id, []).append(device_id)
        return members

    @staticmethod
    def _check_devices(device_ids: list[str], board: dict[str, StatusEntry]) -> None:
        for index, device_id in enumerate(device_ids):
            if device_id not in board:
                raise InvalidInput(f"There is no device {device_id}.", field=f"device_ids.{index}")
