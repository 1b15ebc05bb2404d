"""Which models a car should hold, and how far each one got on the car.

One materialised item per car (fleet table `DEVICE#{id}` / `ASSIGNMENT`) holds the assigned models and the car's
latest report per model, so the car's poll and the staff status table are single GetItems per car.

`md5` in a car's assignment is the md5 of the archive file the car downloads (what it verifies before unpacking);
`model_md5` is the md5 of the model file inside (DeepRacer's `checksum.txt`).
"""
from __future__ import annotations

import time
from collections.abc import Callable
from enum import StrEnum
from typing import Any, Literal, Protocol

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from chalicelib.core.errors import Conflict, Forbidden, NotFound
from chalicelib.core.principals import Device, Principal
from chalicelib.domain.assignment_signals import AssignmentSignals
from chalicelib.domain.racer_models import DOWNLOAD_EXPIRES_S, ModelRecord, ModelService, ModelStatus, utc_now

MAX_MODELS_PER_CAR = 10


class CarModelStatus(StrEnum):
    ASSIGNED = "assigned"  # not reported by the car yet
    DOWNLOADING = "downloading"
    VERIFIED = "verified"
    LOADED = "loaded"
    FAILED = "failed"


class AssignedModel(BaseModel):
    model_config = ConfigDict(frozen=True)
    model_id: str
    name: str
    owner_sub: str
    owner_username: str
    model_md5: str | None
    archive_md5: str | None

    @classmethod
    def of(cls, record: ModelRecord) -> AssignedModel:
        return cls(model_id=record.model_id, name=record.name, owner_sub=record.owner_sub,
                   owner_username=record.owner_username, model_md5=record.model_md5,
                   archive_md5=record.archive_md5)


class ModelProgress(BaseModel):
    model_config = ConfigDict(frozen=True)
    status: CarModelStatus
    reason: str | None = None
    md5: str | None = None
    updated_at: str


class Assignment(BaseModel):
    model_config = ConfigDict(frozen=True)
    device_id: str
    models: list[AssignedModel] = Field(default_factory=list)
    progress: dict[str, ModelProgress] = Field(default_factory=dict)
    assigned_by: str | None = None
    assigned_at: str | None = None
    version: int = 0

    def progress_of(self, model_id: str) -> ModelProgress | None:
        return self.progress.get(model_id)

    def public(self) -> dict[str, Any]:
        return {"device_id": self.device_id, "assigned_by": self.assigned_by, "assigned_at": self.assigned_at,
                "models": [{**model.model_dump(mode="json", exclude={"owner_sub"}),
                            "progress": _progress_json(self.progress_of(model.model_id))}
                           for model in self.models]}


class AssignInput(BaseModel):
    model_config = ConfigDict(extra="forbid")
    model_ids: list[str] = Field(max_length=MAX_MODELS_PER_CAR, description="[] clears the car")

    @field_validator("model_ids")
    @classmethod
    def _unique(cls, model_ids: list[str]) -> list[str]:
        if len(set(model_ids)) != len(model_ids):
            raise ValueError("lists a model twice")
        return model_ids


class StatusReport(BaseModel):
    model_config = ConfigDict(extra="forbid")
    model_id: str = Field(min_length=1, max_length=80)
    status: Literal["downloading", "verified", "loaded", "failed"]
    md5: str | None = Field(default=None, pattern=r"^[0-9a-f]{32}$")
    reason: str | None = Field(default=None, max_length=300)

    @model_validator(mode="after")
    def _complete(self) -> StatusReport:
        if self.status == "verified" and self.md5 is None:
            raise ValueError("a 'verified' report needs the md5 the car computed")
        if self.status == "failed" and not self.reason:
            raise ValueError("a 'failed' report needs a reason")
        return self


MAX_WAIT_S = 20.0  # under API Gateway's 29 s limit; the agent asks again at once
# A waiting car is woken by the write itself (AssignmentSignals); storage is re-read this often only to catch writes
# made elsewhere (another process; on AWS, another Lambda). settings.assignment_recheck_s overrides it.
RECHECK_S = 5.0


class AssignmentQuery(BaseModel):
    """A car that already holds `wait_for_version` waits for the next one: the answer comes the moment staff change
    its assignment (or after `wait_s`, unchanged), so it learns of a new racer at once without polling. The answer's
    `change_seen_by` says how: "push" (the write woke the poll), "recheck" (the storage fallback found it), "at once"
    (it was changed before the car asked) or "deadline" (nothing changed)."""
    model_config = ConfigDict(extra="forbid")
    wait_for_version: int | None = Field(default=None, ge=0)
    wait_s: float = Field(default=0.0, ge=0.0, le=MAX_WAIT_S)


class StatusRow(BaseModel):
    device_id: str
    model_id: str | None
    model_name: str | None
    owner_username: str | None
    status: str
    reason: str | None = None
    updated_at: str | None = None


class AssignmentStore(Protocol):
    def get(self, device_id: str) -> Assignment | None: ...
    def get_many(self, device_ids: list[str]) -> dict[str, Assignment]: ...
    def put(self, assignment: Assignment, *, expected_version: int) -> None: ...
    def record_progress(self, device_id: str, model_id: str, progress: ModelProgress) -> bool: ...


class CarDirectory(Protocol):
    """What assignments need from the fleet registry (implemented over the devices/events storage)."""
    def require_car(self, device_id: str) -> None: ...
    def cars_of_event(self, event_id: str) -> list[str]: ...


class AssignmentChanged(Exception):
    """The assignment item changed between read and write (the store raises it)."""


class AssignmentService:
    def __init__(self, store: AssignmentStore, models: ModelService, cars: CarDirectory,
                 clock: Callable[[], str] = utc_now, *, monotonic: Callable[[], float] = time.monotonic,
                 signals: AssignmentSignals | None = None, recheck_s: float = RECHECK_S) -> None:
        self._store = store
        self._models = models
        self._cars = cars
        self._clock = clock
        self._monotonic = monotonic
        self._signals = signals or AssignmentSignals()
        self._recheck_s = recheck_s

    def assign(self, principal: Principal, device_id: str, model_ids: list[str]) -> Assignment:
        self._cars.require_car(device_id)
        chosen = [AssignedModel.of(self._models.available_model(model_id)) for model_id in model_ids]
        for _attempt in range(3):
            current = self._store.get(device_id) or Assignment(device_id=device_id)
            now = self._clock()
            kept = {m.model_id: current.progress[m.model_id] for m in chosen
                    if m.model_id in current.progress and m.model_id in {c.model_id for c in current.models}}
            progress = {m.model_id: kept.get(m.model_id) or ModelProgress(status=CarModelStatus.ASSIGNED,
                                                                          updated_at=now) for m in chosen}
            updated = Assignment(device_id=device_id, models=chosen, progress=progress, assigned_by=principal.id,
                                 assigned_at=now, version=current.version + 1)
            try:
                self._store.put(updated, expected_version=current.version)
            except AssignmentChanged:
                continue
            self._signals.changed(device_id)
            return updated
        raise Conflict("The car's assignment is changing right now; try again.", field="device_id")

    def for_staff(self, device_id: str) -> Assignment:
        self._cars.require_car(device_id)
        return self._store.get(device_id) or Assignment(device_id=device_id)

    def for_car(self, device: Device, query: AssignmentQuery | None = None) -> dict[str, Any]:
        """The calling car's models with a short-lived download URL each (withdrawn models are left out); with
        `wait_for_version`, once the assignment is another version than that one (or `wait_s` passed)."""
        car = _require_car_device(device)
        mark = self._signals.mark(car.device_id)
        assignment = self._store.get(car.device_id) or Assignment(device_id=car.device_id)
        seen_by: dict[str, str] = {}
        if query is not None and query.wait_for_version is not None:
            assignment, seen_by["change_seen_by"] = self._wait_for_change(car.device_id, assignment, mark, query)
        models, withdrawn = [], []
        for model in assignment.models:
            record = self._models.store.get(model.owner_sub, model.model_id)
            if record is None or record.status is not ModelStatus.AVAILABLE:
                withdrawn.append(model.model_id)
                continue
            models.append({"model_id": model.model_id, "name": model.name, "owner_username": model.owner_username,
                           "folder": f"{model.owner_username}-{model.name}", "md5": record.archive_md5,
                           "model_md5": record.model_md5, "url": self._models.download_url(record),
                           "expires_in": DOWNLOAD_EXPIRES_S,
                           "progress": _progress_json(assignment.progress_of(model.model_id)),
                           **self._converted(record)})
        return {"device_id": car.device_id, "assigned_at": assignment.assigned_at, "version": assignment.version,
                "models": models, "withdrawn": withdrawn, **seen_by}

    def _wait_for_change(self, device_id: str, assignment: Assignment, mark: int,
                         query: AssignmentQuery) -> tuple[Assignment, str]:
        """Sleep until a write to the car's assignment wakes us (or the storage re-read every recheck_s finds one
        made elsewhere, or wait_s ends); the assignment as then stored, and how the change was seen."""
        deadline = self._monotonic() + query.wait_s
        seen_by = "at once"  # the car was behind already
        while assignment.version == query.wait_for_version:
            remaining = deadline - self._monotonic()
            if remaining <= 0:
                return assignment, "deadline"
            woken = self._signals.wait(device_id, mark, min(remaining, self._recheck_s))
            seen_by = "push" if woken else "recheck"
            mark = self._signals.mark(device_id)
            assignment = self._store.get(device_id) or Assignment(device_id=device_id)
        return assignment, seen_by

    def _converted(self, record: ModelRecord) -> dict[str, Any]:
        """Console models: the ONNX conversion too, so a drem car agent can drive them (a DeepRacer takes the .pb)."""
        url = self._models.converted_download_url(record)
        return {"onnx": {"url": url, "md5": record.converted_md5}} if url and record.converted_md5 else {}

    def report(self, device: Device, report: StatusReport) -> ModelProgress:
        car = _require_car_device(device)
        assignment = self._store.get(car.device_id)
        model = next((m for m in (assignment.models if assignment else []) if m.model_id == report.model_id), None)
        if model is None:
            raise NotFound(f"Model {report.model_id!r} is not assigned to this car.", field="model_id")
        progress = ModelProgress(status=CarModelStatus(report.status), reason=report.reason, md5=report.md5,
                                 updated_at=self._clock())
        if report.status == "verified" and model.archive_md5 and report.md5 != model.archive_md5:
            progress = progress.model_copy(update={
                "status": CarModelStatus.FAILED,
                "reason": f"checksum mismatch: the car computed {report.md5}, the archive's md5 is "
                          f"{model.archive_md5}"})
        if not self._store.record_progress(car.device_id, report.model_id, progress):
            raise NotFound(f"Model {report.model_id!r} is no longer assigned to this car.", field="model_id")
        self._signals.changed(car.device_id)
        return progress

    def event_status(self, event_id: str) -> list[StatusRow]:
        """One row per (car, assigned model) over the cars of the event's track fleets; a row per idle car."""
        cars = self._cars.cars_of_event(event_id)
        assignments = self._store.get_many(cars)
        rows: list[StatusRow] = []
        for device_id in cars:
            assignment = assignments.get(device_id)
            if assignment is None or not assignment.models:
                rows.append(StatusRow(device_id=device_id, model_id=None, model_name=None, owner_username=None,
                                      status="unassigned"))
                continue
            for model in assignment.models:
                progress = assignment.progress_of(model.model_id)
                rows.append(StatusRow(device_id=device_id, model_id=model.model_id, model_name=model.name,
                                      owner_username=model.owner_username,
                                      status=progress.status.value if progress else CarModelStatus.ASSIGNED.value,
                                      reason=progress.reason if progress else None,
                                      updated_at=progress.updated_at if progress else assignment.assigned_at))
        return rows


def _require_car_device(device: Principal) -> Device:
    if not isinstance(device, Device) or device.device_kind != "car":
        raise Forbidden("Only a car can read or report its model assignment.")
    return device


def _progress_json(progress: ModelProgress | None) -> dict[str, Any] | None:
    return progress.model_dump(mode="json") if progress else None
