"""Part: whichever pilot is loaded right now. A new model is built completely before it replaces the old one, so the
drive loop never sees a half-loaded model (and keeps the old one if the new one fails to load)."""
from __future__ import annotations

import threading
from pathlib import Path

from drem_cars.model_files import ActionSpace
from drem_cars.parts.pilot_onnx import OnnxPilot


class PilotSlot:
    def __init__(self) -> None:
        self._pilot: OnnxPilot | None = None
        self._lock = threading.Lock()

    def load(self, model_dir: Path) -> OnnxPilot:
        pilot = OnnxPilot(model_dir)  # raises ModelError before anything is swapped
        with self._lock:
            self._pilot = pilot
        return pilot

    def unload(self) -> None:
        with self._lock:
            self._pilot = None

    @property
    def pilot(self) -> OnnxPilot | None:
        return self._pilot

    def action_space(self) -> ActionSpace | None:
        pilot = self._pilot
        return pilot.action_space if pilot is not None else None

    def run(self, image):
        pilot = self._pilot
        if pilot is None:
            return None, None, None
        return pilot.run(image)
