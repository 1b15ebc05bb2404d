"""Driver for our own vehicle loop (simulator, or camera + PWM): models load into the pilot slot, stops and the
throttle cap go to the safety part, the tail light to whatever LED hook the hardware has."""
from __future__ import annotations

from collections.abc import Callable

from drem_cars.model_store import InstalledModel
from drem_cars.parts.pilot_slot import PilotSlot
from drem_cars.parts.safety import Safety
from drem_cars.parts.telemetry import Telemetry


class LocalDriver:
    def __init__(self, pilot: PilotSlot, safety: Safety, telemetry: Telemetry,
                 tail_light: Callable[[str], None] | None = None,
                 battery: Callable[[], float | None] | None = None) -> None:
        self.pilot = pilot
        self.safety = safety
        self.telemetry = telemetry
        self.tail_light_colour: str | None = None
        self._tail_light = tail_light
        self._battery = battery
        self.stop_reason: str | None = None

    def load_model(self, model: InstalledModel) -> None:
        self.pilot.load(model.path)

    def model_lost(self, model: InstalledModel) -> str | None:
        return None  # our own drive loop holds the model in this process: it cannot lose it behind our back

    def reloaded(self, model: InstalledModel) -> None: ...

    def preload(self, model: InstalledModel) -> None: ...  # the model store already holds it, unpacked

    def unload_models(self) -> None:
        self.pilot.unload()

    def delete_all_models(self) -> int:
        self.pilot.unload()  # the agent deletes the files from its model store
        return 0

    def start_car(self) -> None:
        """Staff START_CAR: lifts a staff emergency stop (the loop's other stops still apply)."""
        self.safety.clear_emergency_stop()

    def emergency_stop(self) -> None:
        self.safety.emergency_stop()

    def set_throttle_cap(self, pct: int) -> None:
        self.safety.set_throttle_cap(pct)

    def set_tail_light(self, colour_hex: str) -> str | None:
        self.tail_light_colour = colour_hex
        if self._tail_light is not None:
            self._tail_light(colour_hex)
        return None

    def heartbeat_ok(self) -> None:
        self.safety.heartbeat_ok()

    def battery_pct(self) -> float | None:
        return self._battery() if self._battery is not None else None

    def faults(self) -> list[str]:
        return [f"stopped: {self.stop_reason}"[:120]] if self.stop_reason else []

    def fps(self) -> float | None:
        return self.telemetry.fps()

    def inference_ms(self) -> float | None:
        return self.telemetry.inference_ms()

    def run(self, stopped: bool, reason: str | None) -> None:
        """Also a part (last in the loop): remembers why the car is stopped, for heartbeats."""
        self.stop_reason = reason if stopped else None
