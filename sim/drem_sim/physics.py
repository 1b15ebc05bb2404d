"""Car dynamics of a 1/18-scale DeepRacer on a pymunk body.

A kinematic bicycle with a tyre grip limit: the steered wheels turn the body at
v·tan(δ)/wheelbase, and the tyres can cancel the sideways velocity this creates only up to
friction·g (minus what acceleration already uses: a friction circle). Too fast into a corner,
the car slides wide, which is what sends overspeeding models off the track.
The pose is integrated as pymunk (Chipmunk) integrates a kinematic body: we set its velocities, it moves it.
A kinematic body with no shapes gets nothing else from a Space step, so by default the same arithmetic runs in
plain Python (a tenth of the cost of the cffi round trips); `integrator="pymunk"` steps a real pymunk Space and
tests/sim/test_env_fast_paths.py proves both give bit-identical trajectories. Physics never draws.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import pymunk

GRAVITY = 9.81


@dataclass(frozen=True)
class CarSpec:
    wheelbase: float = 0.164  # m, front hinge to rear axle (simapp URDF)
    axle_track: float = 0.162  # m, left to right wheel centres
    front_axle_x: float = 0.0823  # m ahead of the body origin
    rear_axle_x: float = -0.0817
    front_point_x: float = 0.14  # DeepRacer reports x, y at this point ahead of the origin
    max_steering_deg: float = 30.0
    steering_rate_deg_s: float = 360.0  # servo slew rate
    max_speed: float = 4.0  # m/s
    max_accel: float = 6.0  # m/s² drive
    max_brake: float = 8.0  # m/s² braking
    mass: float = 1.5  # kg (real car; only reported, the kinematic body needs no inertia)
    friction: float = 1.0  # tyre grip coefficient (a track's sim.friction overrides it)


class CarPhysics:
    """One car. `command()` sets the held steering/speed; `step()` advances one fixed physics step."""

    def __init__(self, spec: CarSpec | None = None, dt: float = 1.0 / 60.0, integrator: str = "python") -> None:
        if integrator not in ("python", "pymunk"):
            raise ValueError(f"integrator is 'python' or 'pymunk', not {integrator!r}")
        self.spec = spec or CarSpec()
        self.dt = dt
        self.integrator = integrator
        self.space = pymunk.Space()
        self._body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        self.space.add(self._body)
        self._x = self._y = self._angle = 0.0
        self._cos, self._sin = 1.0, 0.0  # of self._angle, kept with it: the front and wheel points ask every step
        self._max_steer = math.radians(self.spec.max_steering_deg)
        self._steer_step = math.radians(self.spec.steering_rate_deg_s) * dt
        self.reset(0.0, 0.0, 0.0)

    # ---- state ----------------------------------------------------------------------------
    def reset(self, x: float, y: float, heading: float, speed: float = 0.0) -> None:
        """Place the body origin at (x, y) facing `heading` (radians), rolling straight at `speed`."""
        self._body.position = (x, y)
        self._body.angle = heading
        position = self._body.position  # read back: the pose is exactly what pymunk stores
        self._x, self._y, self._angle = position.x, position.y, self._body.angle
        self._cos, self._sin = math.cos(self._angle), math.sin(self._angle)
        self.vx = speed * math.cos(heading)
        self.vy = speed * math.sin(heading)
        self.steer = 0.0
        self.steer_cmd = 0.0
        self.speed_cmd = speed
        self.sliding = False

    @property
    def body(self) -> pymunk.Body:
        """The pymunk body, brought up to date with the pose (for callers that want pymunk's view of the car)."""
        if self.integrator == "python":
            self._body.position = (self._x, self._y)
            self._body.angle = self._angle
        return self._body

    @property
    def x(self) -> float:
        return self._x

    @property
    def y(self) -> float:
        return self._y

    @property
    def heading(self) -> float:
        return self._angle

    @property
    def speed(self) -> float:
        """Measured speed along the car's heading, m/s."""
        return self.vx * self._cos + self.vy * self._sin

    def point_ahead(self, forward: float, left: float = 0.0) -> tuple[float, float]:
        """World position of a point fixed on the car (body frame, metres)."""
        c, s = self._cos, self._sin
        return self._x + forward * c - left * s, self._y + forward * s + left * c

    def front_point(self) -> tuple[float, float]:
        return self.point_ahead(self.spec.front_point_x)

    def wheel_points(self) -> list[tuple[float, float]]:
        """The four wheel contact points: `point_ahead`'s arithmetic with the pose's cos/sin, taken once per pose."""
        sp = self.spec
        half = sp.axle_track / 2
        c, s = self._cos, self._sin
        px, py = self._x, self._y
        return [(px + fx * c - side * s, py + fx * s + side * c)
                for fx in (sp.front_axle_x, sp.rear_axle_x) for side in (half, -half)]

    # ---- control + integration -----------------------------------------------------------
    def command(self, steering_deg: float, speed: float) -> None:
        self.steer_cmd = max(-self._max_steer, min(self._max_steer, math.radians(steering_deg)))
        self.speed_cmd = max(0.0, min(self.spec.max_speed, speed))

    def step(self) -> None:
        sp, dt = self.spec, self.dt
        self.steer += max(-self._steer_step, min(self._steer_step, self.steer_cmd - self.steer))
        c, s = self._cos, self._sin
        v_long = self.vx * c + self.vy * s
        grip = sp.friction * GRAVITY
        accel = (self.speed_cmd - v_long) / dt
        accel = max(-min(sp.max_brake, grip), min(min(sp.max_accel, grip), accel))

        angular_velocity = v_long * math.tan(self.steer) / sp.wheelbase
        if self.integrator == "python":
            # Chipmunk2D src/cpBody.c cpBodyUpdatePosition: p += (v + v_bias)·dt, a += (w + w_bias)·dt, with the
            # biases zero (no shapes, no constraints); a kinematic body skips cpBodyUpdateVelocity.
            self._x = self._x + (self.vx + 0.0) * dt
            self._y = self._y + (self.vy + 0.0) * dt
            self._angle = self._angle + (angular_velocity + 0.0) * dt
        else:
            body = self._body
            body.velocity = (self.vx, self.vy)
            body.angular_velocity = angular_velocity
            self.space.step(dt)
            position = body.position
            self._x, self._y, self._angle = position.x, position.y, body.angle

        # The body turned; the tyres now fight the sideways part of the old velocity.
        heading = self._angle
        c, s = math.cos(heading), math.sin(heading)
        self._cos, self._sin = c, s
        v_long = self.vx * c + self.vy * s + accel * dt
        v_lat = -self.vx * s + self.vy * c
        lateral_budget = math.sqrt(max(0.0, grip * grip - accel * accel)) * dt
        self.sliding = abs(v_lat) > lateral_budget
        v_lat = 0.0 if not self.sliding else v_lat - math.copysign(lateral_budget, v_lat)
        v_long = max(0.0, v_long)
        self.vx = v_long * c - v_lat * s
        self.vy = v_long * s + v_lat * c
