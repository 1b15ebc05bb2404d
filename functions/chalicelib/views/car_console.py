"""What the operator console's cars page shows: every device with its status, fleet and assigned models, and the
models an operator can give a car. Built from the same services the JSON API uses.

Racers are named by their display names, told apart as everywhere else (drem_leaderboard.names) among every racer the
page names: the owners of the assigned models and of the models on offer, so a chip and the choices name one racer
alike, and the page's 2-second poll (which rebuilds the chips) names them as the page did."""
from __future__ import annotations

from datetime import UTC, datetime

from pydantic import BaseModel

from chalicelib.core.principals import User
from chalicelib.domain.assignments import AssignmentService, CarModelStatus
from chalicelib.domain.devices import (
    TAIL_LIGHT_PALETTE,
    CarVideoSettings,
    Command,
    CommandStatus,
    DeviceKind,
    DeviceService,
    DeviceView,
)
from chalicelib.domain.fleets import FleetService
from chalicelib.domain.racer_models import ListQuery, ModelService, ModelStatus
from chalicelib.views.racer_names import ProfilesBySub, shown_racer_names


class AssignedLine(BaseModel):
    model_id: str
    owner_sub: str
    owner_username: str
    model: str  # the model's name and how far it got: "fast-one (loaded)"
    racer: str = ""  # how the page names its owner (set by `cars_overview`)

    @property
    def text(self) -> str:
        return f"{self.racer or self.owner_username} · {self.model}"


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
    assigned: list[AssignedLine]
    # What the car's last heartbeat said is wrong (e.g. someone else holds a DeepRacer's console).
    faults: list[str] = []
    last_command: str = ""
    last_command_state: str = ""  # pending | ok | failed: the page colours it
    video: CarVideoSettings = CarVideoSettings()  # the camera on the stream (the defaults until staff choose)


class ModelChoice(BaseModel):
    model_id: str
    owner_sub: str
    owner_username: str
    name: str
    racer: str = ""  # how the page names its owner (set by `cars_overview`)

    @property
    def label(self) -> str:
        return f"{self.racer or self.owner_username} · {self.name}"


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


COMMAND_LABELS = {"RESTART_SERVICE": "Restart", "EMERGENCY_STOP": "Emergency stop", "START_CAR": "Start car",
                  "SET_TAIL_LIGHT": "Tail light",
                  "DELETE_ALL_MODELS": "Delete models", "SET_THROTTLE_CAP": "Throttle cap"}
_COMMAND_STATES = {CommandStatus.PENDING: "sent, waiting for the car", CommandStatus.OK: "done by the car",
                   CommandStatus.FAILED: "failed"}


def command_text(command: Command | None, now_ms: int) -> tuple[str, str]:
    """("Emergency stop: done by the car 3 s ago", "ok") for the device's newest command; ("", "") for none."""
    if command is None:
        return "", ""
    at = command.acked_at_ms or command.created_at_ms
    ago = f" {max(0, now_ms - at) // 1000} s ago" if now_ms - at < 3_600_000 else ""
    failed = f": {command.message}" if command.status is CommandStatus.FAILED and command.message else ""
    label = COMMAND_LABELS.get(command.type.value, command.type.value.replace("_", " ").capitalize())
    return f"{label}: {_COMMAND_STATES[command.status]}{failed}{ago}", command.status.value


def car_line(view: DeviceView, fleet_names: dict[str, str], assignments: AssignmentService, devices: DeviceService,
             now_ms: int) -> CarLine:
    telemetry = view.telemetry
    assigned: list[AssignedLine] = []
    loaded_by_progress = ""
    if view.kind is DeviceKind.CAR:
        assignment = assignments.for_staff(view.device_id)
        running = telemetry.model if telemetry else None
        for model in assignment.models:
            progress = assignment.progress_of(model.model_id)
            state = progress.status.value if progress else "assigned"
            if progress and progress.status is CarModelStatus.LOADED:
                loaded_by_progress = loaded_by_progress or model.name
            said = f": {progress.reason}" if progress and progress.reason else ""  # why it failed, or was reloaded
            # A car holds several models but drives one: "loaded" is the one its heartbeat names, the others it
            # reported loaded are only "on the car".
            if running is not None and model.archive_md5 and running.md5 == model.archive_md5:
                state = "loaded"
            elif running is not None and state == "loaded":
                state = "on the car"
            assigned.append(AssignedLine(model_id=model.model_id, owner_sub=model.owner_sub,
                                         owner_username=model.owner_username, model=f"{model.name} ({state}{said})"))
    commands = devices.device_commands(view.device_id)
    last, state = command_text(max(commands, key=lambda c: c.command_id) if commands else None, now_ms)
    return CarLine(
        device_id=view.device_id, kind=view.kind.value, hostname=view.hostname, fleet_id=view.fleet_id or "",
        fleet_name=fleet_names.get(view.fleet_id or "", "no fleet"), online=view.online,
        last_seen=seen_text(view),
        # The car's heartbeat names its loaded model; its model report says the same a moment earlier.
        loaded_model=(telemetry.model.name if telemetry and telemetry.model else loaded_by_progress) or "—",
        battery=f"{telemetry.battery_pct:.0f} %" if telemetry and telemetry.battery_pct is not None else "—",
        assigned=assigned, faults=list(telemetry.faults) if telemetry else [], last_command=last,
        last_command_state=state, video=view.video or CarVideoSettings())


def cars_overview(principal: User, devices: DeviceService, fleets: FleetService, assignments: AssignmentService,
                  models: ModelService, profiles: ProfilesBySub, now_ms: int) -> CarsOverview:
    fleet_names = {f.fleet_id: f.name for f in fleets.list_fleets()}
    lines = [car_line(view, fleet_names, assignments, devices, now_ms) for view in devices.list_devices()]
    page = models.list_models(principal, ListQuery(limit=100))
    choices = [ModelChoice(model_id=m.model_id, owner_sub=m.owner_sub, owner_username=m.owner_username, name=m.name)
               for m in page.models if m.status is ModelStatus.AVAILABLE]
    racer = shown_racer_names([(a.owner_sub, a.owner_username) for line in lines for a in line.assigned]
                         + [(c.owner_sub, c.owner_username) for c in choices], profiles)
    lines = [line.model_copy(update={"assigned": [a.model_copy(update={"racer": racer[a.owner_sub]})
                                                  for a in line.assigned]}) for line in lines]
    choices = [c.model_copy(update={"racer": racer[c.owner_sub]}) for c in choices]
    return CarsOverview(cars=lines, fleets=sorted(fleet_names.items(), key=lambda item: item[1].lower()),
                        models=choices, tail_lights=[(name, name) for name in TAIL_LIGHT_PALETTE] + [("#FFFFFF",
                                                                                                      "white")])

