"""What an operator (or the clock) can ask of a race. A discriminated union, so a JSON body parses straight into one."""
from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter


class _Command(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Start(_Command):
    kind: Literal["start"] = "start"


class Pause(_Command):
    kind: Literal["pause"] = "pause"


class Resume(_Command):
    kind: Literal["resume"] = "resume"


class Toggle(_Command):
    """DREM's single Start/Pause/Resume button."""

    kind: Literal["toggle"] = "toggle"


class CaptureLap(_Command):
    """The operator's "Capture lap" button: the lap time is the race clock since the lap began."""

    kind: Literal["capture_lap"] = "capture_lap"
    car: str | None = Field(default=None, max_length=128)


class DidNotFinish(_Command):
    kind: Literal["dnf"] = "dnf"
    car: str | None = Field(default=None, max_length=128)


class AddReset(_Command):
    kind: Literal["reset_add"] = "reset_add"


class RemoveReset(_Command):
    kind: Literal["reset_remove"] = "reset_remove"


class UndoFalseFinish(_Command):
    kind: Literal["undo_false_finish"] = "undo_false_finish"


class SetLapValidity(_Command):
    kind: Literal["set_lap_validity"] = "set_lap_validity"
    lap_id: int = Field(ge=0)
    is_valid: bool


class SelectCar(_Command):
    kind: Literal["select_car"] = "select_car"
    car: str | None = Field(default=None, max_length=128)


class Tick(_Command):
    """Look at the clock: flags the race time as expired once it has run out."""

    kind: Literal["tick"] = "tick"


class End(_Command):
    kind: Literal["end"] = "end"


class Reopen(_Command):
    """DREM's "Cancel" in the end-race dialog: back to paused (or ready if it never started)."""

    kind: Literal["reopen"] = "reopen"


class Submit(_Command):
    kind: Literal["submit"] = "submit"


class Discard(_Command):
    kind: Literal["discard"] = "discard"


RaceCommand = Annotated[
    Start
    | Pause
    | Resume
    | Toggle
    | CaptureLap
    | DidNotFinish
    | AddReset
    | RemoveReset
    | UndoFalseFinish
    | SetLapValidity
    | SelectCar
    | Tick
    | End
    | Reopen
    | Submit
    | Discard,
    Field(discriminator="kind"),
]

race_command_adapter: TypeAdapter[RaceCommand] = TypeAdapter(RaceCommand)


def parse_command(payload: object) -> RaceCommand:
    """Parse a decoded JSON body such as ``{"kind": "capture_lap"}``; raises pydantic.ValidationError."""
    return race_command_adapter.validate_python(payload)
