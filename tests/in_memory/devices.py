"""The device registry, activation codes and the status board in memory: the ports FleetService, DeviceService
(except commands) and ActivationService take.

Copies chalicelib/storage/devices.py (DynamoDeviceStore): `redeem` is all-or-nothing (the code is marked, the device
registered and its status line put only when the code exists, is not yet redeemed, has not expired, and names the
device's kind and hostname, case-insensitively, and the device id is free); `set_fleet` of a device that is gone does
nothing; a device's status line follows its fleet, and is put from the registry when it was missing; deleting a
device takes its line with it; a heartbeat stamps only an existing line. Reads hand out copies.
Commands (put_command, commands, ack_command) are not here yet: DeviceService's command flow stays on tests/unit.
"""
from __future__ import annotations

from chalicelib.domain.activation import ActivationExchange, ActivationRecord
from chalicelib.domain.devices import DeviceRecord, StatusEntry, Telemetry


class InMemoryDeviceStore:
    def __init__(self) -> None:
        self._devices: dict[str, str] = {}  # device id -> DeviceRecord JSON
        self._codes: dict[str, str] = {}  # code hash -> ActivationRecord JSON
        self._board: dict[str, str] = {}  # device id -> StatusEntry JSON

    # --- registry ---
    def get_device(self, device_id: str) -> DeviceRecord | None:
        found = self._devices.get(device_id)
        return DeviceRecord.model_validate_json(found) if found else None

    def delete_device(self, device_id: str) -> None:
        self._devices.pop(device_id, None)
        self._board.pop(device_id, None)

    def set_fleet(self, device_id: str, fleet_id: str | None) -> None:
        record = self.get_device(device_id)
        if record is None:
            return  # deregistered meanwhile: nothing to move
        record = record.model_copy(update={"fleet_id": fleet_id or None})
        self._devices[device_id] = record.model_dump_json()
        line = self._board.get(device_id)
        entry = (StatusEntry.model_validate_json(line).model_copy(update={"fleet_id": fleet_id or None})
                 if line else StatusEntry.for_device(record))
        self._board[device_id] = entry.model_dump_json()

    def replace_secret_hash(self, device_id: str, secret_hash: str) -> bool:
        record = self.get_device(device_id)
        if record is None:
            return False
        self._devices[device_id] = record.model_copy(update={"secret_hash": secret_hash}).model_dump_json()
        return True

    # --- activation codes ---
    def put_activation(self, record: ActivationRecord) -> None:
        # The adapter writes the code's own fields only: a put over a redeemed code starts it afresh.
        fresh = record.model_copy(update={"redeemed_device_id": None, "redeemed_attempt_hash": None})
        self._codes[record.code_hash] = fresh.model_dump_json()

    def get_activation(self, code_hash: str) -> ActivationRecord | None:
        found = self._codes.get(code_hash)
        return ActivationRecord.model_validate_json(found) if found else None

    def redeem(self, code_hash: str, exchange: ActivationExchange, now_ms: int, device: DeviceRecord,
               line: StatusEntry, attempt_hash: str | None) -> bool:
        code = self.get_activation(code_hash)
        if (code is None or code.redeemed_device_id is not None or code.expires_at_ms <= now_ms
                or code.device_kind != exchange.device_kind or code.hostname.lower() != exchange.hostname.lower()
                or device.device_id in self._devices):
            return False
        marks: dict[str, str | None] = {"redeemed_device_id": device.device_id}
        if attempt_hash:
            marks["redeemed_attempt_hash"] = attempt_hash
        self._codes[code_hash] = code.model_copy(update=marks).model_dump_json()
        self._devices[device.device_id] = device.model_dump_json()
        self._board[device.device_id] = line.model_dump_json()
        return True

    # --- status board ---
    def status_board(self) -> dict[str, StatusEntry]:
        return {device_id: StatusEntry.model_validate_json(line) for device_id, line in self._board.items()}

    def put_status_entry(self, entry: StatusEntry) -> None:
        self._board[entry.device_id] = entry.model_dump_json()

    def record_heartbeat(self, device_id: str, now_ms: int, telemetry: Telemetry) -> bool:
        line = self._board.get(device_id)
        if line is None:
            return False
        stamped = StatusEntry.model_validate_json(line).model_copy(update={"last_seen_ms": now_ms,
                                                                          "telemetry": telemetry})
        self._board[device_id] = stamped.model_dump_json()
        return True
