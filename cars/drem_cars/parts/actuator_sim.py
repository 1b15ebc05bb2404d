"""Part: the simulated steering servo and motor. Unit steering/throttle (what PWM would get) drive the sim car.

Unit steering × the car's 30° lock gives the wheel angle; unit throttle × `full_throttle_mps` gives the speed held,
as a motor's duty cycle would (so, as on a real DeepRacer, action-space speeds are relative).
"""
from __future__ import annotations

from drem_cars.parts.sim_world import SimWorld


class SimActuator:
    def __init__(self, world: SimWorld, full_throttle_mps: float = 2.0, max_steering_deg: float = 30.0) -> None:
        self.world = world
        self.full_throttle_mps = full_throttle_mps
        self.max_steering_deg = max_steering_deg

    def run(self, steering: float | None, throttle: float | None) -> None:
        self.world.command((steering or 0.0) * self.max_steering_deg,
                           max(0.0, throttle or 0.0) * self.full_throttle_mps)
        self.world.advance()


class SimLineFollower:
    """Part: a stand-in pilot for the simulator when no model is loaded: the simulator's demonstrator steers
    (pure pursuit on the centre line) at a fixed relative speed, output like a model's (steering degrees, speed)."""

    def __init__(self, world: SimWorld, speed: float = 1.0) -> None:
        from drem_sim.demonstrator import Demonstrator

        self.world = world
        self.speed = speed
        self._demonstrator = Demonstrator(world.track)

    def run(self) -> tuple[float, float]:
        return self._demonstrator.act(self.world.params)["steering_angle"], self.speed
