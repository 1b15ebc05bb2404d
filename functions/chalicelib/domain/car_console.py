"""What the operator console's cars page shows: every device with its status, fleet and assigned models, and the
models an operator can give a car. Built from the same services the JSON API uses."""
from __future__ import annotations

from datetime import UTC, datetime

from pydantic import BaseModel

from chalicelib.auth.principals import User
from chalicelib.domain.assignments import AssignmentService
from chalicelib.domain.devices import TAIL_LIGHT_PALETTE, DeviceKind, DeviceService, DeviceView
from chalicelib.domain.fleets import FleetService
from chalicelib.domain.models import ListQuery, ModelService, ModelStatus


class AssignedLine(BaseModel):
    model_id: str
    text: str


class CarLine(BaseModel):
    device_id: str
    kind: str
    hostname: str
    fleet_id: str
    fleet_name: str
    online: bool
    last_seen: str
    loaded_model: str
    battery: str
    faults: list[str]  # what the car's last heartbeat said is wrong (e.g. someone else holds a DeepRacer's console)
    assigned: list[AssignedLine]


class ModelChoice(BaseModel):
    model_id: str
    label: str


class CarsOverview(BaseModel):
    cars: list[CarLine]
    fleets: list[tuple[str, str]]
    models: list[ModelChoice]
    tail_lights: list[tuple[str, str]]


def seen_text(view: DeviceView) -> str:
    if view.last_seen_ms is None:
        return "never"
    seconds = view.seconds_since_seen or 0
    stamp = datetime.fromtimestamp(view.last_seen_ms / 1000, tz=UTC).strftime("%H:%M:%S UTC")
    return f"{seconds:.0f} s ago ({stamp})" if seconds < 3600 else stamp


def cars_overview(principal: User, devices: DeviceService, fleets: FleetService, assignments: AssignmentService,
                  models: ModelService) -> CarsOverview:
    fleet_names = {f.fleet_id: f.name for f in fleets.list_fleets()}
    lines = []
    for view in devices.list_devices():
        telemetry = view.telemetry
        assigned: list[AssignedLine] = []
        if view.kind is DeviceKind.CAR:
            assignment = assignments.for_staff(view.device_id)
            for model in assignment.models:
                progress = assignment.progress_of(model.model_id)
                state = progress.status.value if progress else "assigned"
                assigned.append(AssignedLine(model_id=model.model_id,
                                             text=f"{model.owner_username} · {model.name} ({state})"))
        lines.append(CarLine(
            device_id=view.device_id, kind=view.kind.value, hostname=view.hostname, fleet_id=view.fleet_id or "",
            fleet_name=fleet_names.get(view.fleet_id or "", "no fleet"), online=view.online,
            last_seen=seen_text(view),
            loaded_model=telemetry.model.name if telemetry and telemetry.model else "—",
            battery=f"{telemetry.battery_pct:.0f} %" if telemetry and telemetry.battery_pct is not None else "—",
            faults=list(telemetry.faults) if telemetry else [], assigned=assigned))
    page = models.list_models(principal, ListQuery(limit=100))
    choices = [ModelChoice(model_id=m.model_id, label=f"{m.owner_username} · {m.name}")
               for m in page.models if m.status is ModelStatus.AVAILABLE]
    return CarsOverview(cars=lines, fleets=sorted(fleet_names.items(), key=lambda item: item[1].lower()),
                        models=choices, tail_lights=[(name, name) for name in TAIL_LIGHT_PALETTE] + [("#FFFFFF", "white")])
