"""DeepRacer's navigation mapping: action (steering degrees, speed) → unit steering and unit throttle.

steering = angle / the car's steering scale (the largest |angle| of a discrete space; `high` of a continuous one, as
aws-deepracer-navigation-pkg deepracer_navigation_node.py get_max_scaled_value divides); throttle follows its curve
y = a·v² + b·v with vmax/2 → 0.8 and vmax → 1.0, so action-space speeds are relative on a real car (m/s are not
honoured); the staff throttle cap scales it afterwards (the safety part).
"""
from __future__ import annotations

from collections.abc import Callable

from drem_cars.model_files import ActionSpace


def unit_throttle(speed: float, max_speed: float) -> float:
    if max_speed <= 0:
        return 0.0
    a = (2 * 1.0 - 4 * 0.8) / (max_speed * max_speed)
    b = (4 * 0.8 - 1.0) / max_speed
    return max(-1.0, min(1.0, a * speed * speed + b * speed))


def unit_steering(steering_deg: float, scale: float) -> float:
    """The navigation node's angle / scale (0.0 for a scale <= 0, as the node answers), held to the servo's -1..1."""
    if scale <= 0:
        return 0.0
    return max(-1.0, min(1.0, steering_deg / scale))


class ActionToDrive:
    """Part: (steering_deg, speed) → (unit steering, unit throttle); the action space comes from the loaded model."""

    def __init__(self, action_space: Callable[[], ActionSpace | None]) -> None:
        self._action_space = action_space

    def run(self, steering_deg: float | None, speed: float | None) -> tuple[float, float]:
        space = self._action_space()
        if steering_deg is None or speed is None or space is None:
            return 0.0, 0.0
        return unit_steering(steering_deg, space.steering_scale), unit_throttle(speed, space.max_speed)
