"""Driver for a stand-alone timer (Raspberry Pi with strips): no motor, no model; faults only."""
from __future__ import annotations

from drem_cars.model_store import InstalledModel


class TimerDriver:
    def load_model(self, model: InstalledModel) -> None:
        raise RuntimeError("a timer does not run models")

    def model_lost(self, model: InstalledModel) -> str | None:
        return None

    def reloaded(self, model: InstalledModel) -> None: ...

    def preload(self, model: InstalledModel) -> None: ...  # the model store already holds it, unpacked

    def unload_models(self) -> None: ...

    def delete_all_models(self) -> int:
        return 0

    def start_car(self) -> None: ...
    def emergency_stop(self) -> None: ...
    def set_throttle_cap(self, pct: int) -> None: ...

    def set_tail_light(self, colour_hex: str) -> str | None:
        return None

    def heartbeat_ok(self) -> None: ...

    def battery_pct(self) -> float | None:
        return None

    def faults(self) -> list[str]:
        return []

    def fps(self) -> float | None:
        return None

    def inference_ms(self) -> float | None:
        return None
