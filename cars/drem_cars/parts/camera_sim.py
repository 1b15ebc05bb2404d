"""Part: the simulated camera. Renders the car's view, stamps it, and hands over timing-line crossings."""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from drem_cars.parts.sim_world import SimWorld


class SimCamera:
    def __init__(self, world: SimWorld, clock: Callable[[], float] = time.monotonic) -> None:
        self.world = world
        self._clock = clock

    def run(self) -> tuple[np.ndarray, float, list[tuple[int, int]]]:
        return self.world.render(), self._clock(), self.world.drain_crossings()
