"""Composition root of the simulated car: which parts, in which order, on which channels.

    camera → [model pilot | stand-in line follower] → action→drive mapping → safety → actuator
           → strip events (virtual timing line) → telemetry → driver status
"""
from __future__ import annotations

from dataclasses import dataclass

from drem_cars import channels as ch
from drem_cars.drivers.local import LocalDriver
from drem_cars.model_files import ActionSpace
from drem_cars.outbox import Outbox
from drem_cars.parts.actuator_sim import SimActuator, SimLineFollower
from drem_cars.parts.camera_sim import SimCamera
from drem_cars.parts.drive_mapping import ActionToDrive
from drem_cars.parts.pilot_slot import PilotSlot
from drem_cars.parts.safety import Safety
from drem_cars.parts.sim_world import SimWorld
from drem_cars.parts.strips import StripEventsToOutbox
from drem_cars.parts.telemetry import Telemetry
from drem_cars.vehicle import Vehicle
from drem_cars.video_sources import FrameTap

# The stand-in driver's action space: speeds 0..1 relative, steering ±30°.
LINE_FOLLOWER_SPACE = ActionSpace("continuous", steering=(-30.0, 30.0), speed=(0.0, 1.0))


class PilotPresence:
    def __init__(self, slot: PilotSlot) -> None:
        self.slot = slot

    def run(self) -> tuple[bool, bool]:
        loaded = self.slot.pilot is not None
        return loaded, not loaded


@dataclass
class SimCar:
    vehicle: Vehicle
    world: SimWorld
    driver: LocalDriver
    safety: Safety
    strips: StripEventsToOutbox | None
    camera_tap: FrameTap  # the rendered camera's newest frame, for the video relay


def build_sim_car(track: str, *, safety: Safety | None = None, outbox: Outbox | None = None,
                  event_id: str | None = None, track_id: str = "1", device_id: str = "sim",
                  full_throttle_mps: float = 2.0, line_follower_speed: float = 0.75) -> SimCar:
    world = SimWorld(track, device_id=device_id)
    slot = PilotSlot()
    safety = safety or Safety()
    telemetry = Telemetry()
    driver = LocalDriver(slot, safety, telemetry)
    vehicle = Vehicle()
    vehicle.add(SimCamera(world), outputs=[ch.CAMERA_IMAGE, ch.CAMERA_FRAME_TIME, ch.SIM_LAP_CROSSINGS])
    tap = FrameTap()
    vehicle.add(tap, inputs=[ch.CAMERA_IMAGE], name="CameraTap")
    vehicle.add(PilotPresence(slot), outputs=[ch.PILOT_ENABLED, ch.PILOT_ABSENT])
    vehicle.add(slot, inputs=[ch.CAMERA_IMAGE], outputs=[ch.PILOT_STEERING, ch.PILOT_SPEED, ch.PILOT_INFERENCE_MS],
                run_condition=ch.PILOT_ENABLED, name="OnnxPilot")
    vehicle.add(SimLineFollower(world, line_follower_speed), outputs=[ch.PILOT_STEERING, ch.PILOT_SPEED],
                run_condition=ch.PILOT_ABSENT)
    vehicle.add(ActionToDrive(lambda: slot.action_space() or LINE_FOLLOWER_SPACE),
                inputs=[ch.PILOT_STEERING, ch.PILOT_SPEED], outputs=[ch.DRIVE_STEERING, ch.DRIVE_THROTTLE])
    vehicle.add(safety, inputs=[ch.DRIVE_STEERING, ch.DRIVE_THROTTLE, ch.CAMERA_FRAME_TIME],
                outputs=[ch.DRIVE_STEERING, ch.DRIVE_THROTTLE, ch.SAFETY_STOPPED, ch.SAFETY_REASON])
    vehicle.add(SimActuator(world, full_throttle_mps), inputs=[ch.DRIVE_STEERING, ch.DRIVE_THROTTLE])
    strips = None
    if outbox is not None and event_id is not None:
        strips = StripEventsToOutbox(outbox, event_id, track_id, device_id)
        vehicle.add(strips, inputs=[ch.SIM_LAP_CROSSINGS])
    vehicle.add(telemetry, inputs=[ch.CAMERA_FRAME_TIME, ch.PILOT_INFERENCE_MS],
                outputs=[ch.TELEMETRY_FPS, ch.TELEMETRY_INFERENCE_MS])
    vehicle.add(driver, inputs=[ch.SAFETY_STOPPED, ch.SAFETY_REASON])
    return SimCar(vehicle, world, driver, safety, strips, tap)
