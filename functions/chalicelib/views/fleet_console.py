"""What the operator console's Fleets page shows: each fleet, how many devices and cars it holds, and the camera
setting its cars share (the fleet's camera form starts at it), from the same services the JSON API uses."""
from __future__ import annotations

from pydantic import BaseModel

from chalicelib.domain.devices import CarVideoSettings, DeviceKind, DeviceView
from chalicelib.domain.fleets import Fleet
from chalicelib.views.camera_choice import cars_text, video_text


class FleetLine(BaseModel):
    fleet_id: str
    name: str
    devices: int
    cars: int
    created_by: str
    video: CarVideoSettings  # what its cars are set to, when they all agree; else the defaults
    cars_agree: bool

    @property
    def camera_text(self) -> str:
        """Under the fleet's camera form: what its cars are set to now."""
        if not self.cars:
            return "No cars in this fleet yet."
        if self.cars_agree:
            whose = "car is" if self.cars == 1 else f"{cars_text(self.cars)} are"
            return f"Its {whose} set to {video_text(self.video)}."
        return f"Its {cars_text(self.cars)} are set differently; this sets them all alike."


def fleet_lines(fleets: list[Fleet], devices: list[DeviceView]) -> list[FleetLine]:
    lines = []
    for fleet in fleets:
        cars = [d for d in devices if d.fleet_id == fleet.fleet_id and d.kind is DeviceKind.CAR]
        # A car staff never set counts as the defaults, as its row on the Cars page shows it.
        settings = {d.video or CarVideoSettings() for d in cars}
        lines.append(FleetLine(fleet_id=fleet.fleet_id, name=fleet.name, devices=len(fleet.device_ids), cars=len(cars),
                               created_by=fleet.created_by, video=next(iter(settings)) if len(settings) == 1
                               else CarVideoSettings(), cars_agree=len(settings) <= 1))
    return lines


def fleet_video_notice(fleet_name: str, cars: int, video: CarVideoSettings) -> str:
    """After the fleet's camera form: how many cars got it (a fleet of timers only has none)."""
    if not cars:
        return f"{fleet_name} has no cars: no camera was set."
    return (f"Camera settings ({video_text(video)}) saved for the {cars_text(cars)} of {fleet_name}; "
            "each sends at them within about 10 seconds.")
