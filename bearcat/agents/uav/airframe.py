"""A multirotor as thesis 6.2.2 models it: a point mass driven by a bounded
acceleration (x'' = a), with the speed and climb limits of a small
quadrotor, an optional wind, and a battery that drains with time in the air.

The position controller flies a braking curve, horizontally and vertically:
the commanded velocity points at the target and is never more than what
the acceleration limit can still stop before it (sqrt(2 a d)), and the
curve's own rate of change is fed forward, so the velocity loop's lag never
carries the vehicle past it and the vehicle arrives without overshooting
the way a tuned PX4 position loop does. Wind is a mean plus a
first-order Gauss-Markov gust; the controller rejects the mean (as the
autopilot's integrator does), paying for it in power (the battery drains
with the airspeed, not the ground speed), but not the gusts, which leave
the hover error of 1-2 m the thesis reports for its quadrotors. Without
gusts the ground acceleration never exceeds ``max_accel``. Everything is in local
metres, x east, y north, z up, relative to home on the ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ARRIVED = 0.5  # m: within this of a position target counts as there
BRAKING = 0.8  # fraction of the horizontal acceleration limit the braking curve plans with
MAX_STEP = 0.05  # s: longer steps are split, so a late tick cannot destabilise the loops


@dataclass(frozen=True)
class Airframe:
    """Limits of the vehicle; the defaults are a Pelican-class quadrotor."""

    max_speed: float = 8.0  # m/s horizontal
    max_accel: float = 3.0  # m/s^2 horizontal
    max_climb: float = 3.0  # m/s
    max_descent: float = 1.5  # m/s
    response: float = 0.5  # s, time constant of the velocity loop
    wind: tuple[float, float] = (0.0, 0.0)  # m/s mean, east and north
    gust: float = 0.0  # m/s, standard deviation of the gusts
    gust_tau: float = 5.0  # s, their correlation time
    drag: float = 0.3  # 1/s: how hard a gust pushes the vehicle (acceleration per m/s of gust)
    endurance: float = 1200.0  # s of hover on a full battery
    speed_drain: float = 0.02  # extra fraction of hover power per m/s of speed


@dataclass
class Body:
    """Where the vehicle is and how it moves."""

    position: np.ndarray  # m (east, north, up)
    velocity: np.ndarray  # m/s
    battery: float = 1.0  # fraction of charge left

    @classmethod
    def at_rest(cls, x: float = 0.0, y: float = 0.0) -> Body:
        return cls(np.array([x, y, 0.0]), np.zeros(3))


class PointMass:
    """Integrates a ``Body`` under velocity or position setpoints."""

    def __init__(self, airframe: Airframe, body: Body, rng: np.random.Generator) -> None:
        self.airframe = airframe
        self.body = body
        self.rng = rng
        self.gust = np.zeros(2)

    def step(self, dt: float, *, target=None, velocity=None, motors: bool = True, landing: bool = False) -> None:
        """Advance ``dt`` seconds toward a position ``target`` (east, north, up)
        or at a ``velocity`` setpoint; ``landing`` holds the target's east and
        north and descends at the full rate, since PX4 lets the ground stop a
        landing rather than braking before it; with the motors off the
        vehicle stays on the ground (or falls, if it was flying)."""
        if dt <= 0:
            return
        parts = math.ceil(dt / MAX_STEP)
        for _ in range(parts):
            self._advance(dt / parts, target, velocity, motors, landing)

    def _advance(self, dt: float, target, velocity, motors: bool, landing: bool) -> None:
        f = self.airframe
        b = self.body
        self._blow(dt)
        if not motors:
            b.velocity[:] = 0.0 if b.position[2] <= 0 else (0.0, 0.0, -max(f.max_descent, 9.81 * dt))
        else:
            if target is not None:
                desired, feedforward = self._approach(target)
                if landing:
                    desired[2], feedforward[2] = -f.max_descent, 0.0
            else:
                desired, feedforward = _limit(np.asarray(velocity, float), f), np.zeros(3)
            # The controller tracks the setpoint through a first-order loop
            # within the acceleration limit, plus the setpoint's own rate of
            # change, so the loop's lag never carries the vehicle past the
            # braking curve; the mean wind's drag is cancelled (an
            # integrator's job), the gusts' drag is not.
            command = (desired - b.velocity) / f.response + feedforward
            command[:2] = _clip_norm(command[:2], f.max_accel)
            command[:2] += f.drag * self.gust
            b.velocity += command * dt
            b.velocity[2] = min(max(b.velocity[2], -f.max_descent), f.max_climb)
        b.position += b.velocity * dt
        if b.position[2] <= 0.0:
            b.position[2] = 0.0
            b.velocity[:] = 0.0
        if motors:
            power = 1.0 + f.speed_drain * float(np.hypot(*(b.velocity[:2] - np.asarray(f.wind))))
            b.battery = max(0.0, b.battery - power * dt / f.endurance)

    def at(self, target) -> bool:
        """Whether the vehicle has arrived at ``target`` and slowed down."""
        near = np.linalg.norm(self.body.position - np.asarray(target, float)) <= ARRIVED
        return bool(near and np.linalg.norm(self.body.velocity) <= 0.3)

    def _approach(self, target) -> tuple[np.ndarray, np.ndarray]:
        """The velocity to fly toward ``target`` and its rate of change as the
        vehicle moves: the speed along each axis's braking curve, capped by the
        speed limits."""
        f = self.airframe
        # Near the target the position loop closes at the velocity loop's
        # rate; with the setpoint's rate fed forward both poles sit at
        # -1/response (critically damped), so the approach is monotone.
        gain = 1.0 / f.response
        offset = np.asarray(target, float) - self.body.position
        v = self.body.velocity
        desired, feedforward = np.zeros(3), np.zeros(3)
        d = float(np.hypot(*offset[:2]))
        if d > 1e-6:
            along = offset[:2] / d
            speed, slope = _braking(d, f.max_speed, BRAKING * f.max_accel, gain)
            closing = float(along @ v[:2])
            desired[:2] = along * speed
            # The speed changes as the distance shrinks, the direction as the
            # vehicle moves across the line to the target.
            feedforward[:2] = -along * slope * closing - (speed / d) * (v[:2] - along * closing)
        else:
            feedforward[:2] = -gain * v[:2]
        dz = float(offset[2])
        speed, slope = _braking(abs(dz), f.max_climb if dz > 0 else f.max_descent, f.max_accel, gain)
        desired[2] = math.copysign(speed, dz)
        feedforward[2] = -slope * v[2]
        return desired, feedforward

    def _blow(self, dt: float) -> None:
        f = self.airframe
        if f.gust > 0:
            a = math.exp(-dt / f.gust_tau)
            self.gust = a * self.gust + f.gust * math.sqrt(1 - a * a) * self.rng.normal(size=2)


def _braking(distance: float, top_speed: float, accel: float, gain: float) -> tuple[float, float]:
    """The fastest speed that can still stop in ``distance`` decelerating at
    ``accel`` and closes in as ``gain * distance`` near the target (the
    curve sqrt(c^2 + 2 a d) - c with c = a / gain), capped at ``top_speed``;
    and its slope, d(speed)/d(distance)."""
    c = accel / gain
    root = math.sqrt(c * c + 2.0 * accel * distance)
    if root - c >= top_speed:
        return top_speed, 0.0
    return root - c, accel / root


def _limit(velocity: np.ndarray, f: Airframe) -> np.ndarray:
    v = velocity.copy()
    v[:2] = _clip_norm(v[:2], f.max_speed)
    v[2] = min(max(v[2], -f.max_descent), f.max_climb)
    return v


def _clip_norm(v: np.ndarray, limit: float) -> np.ndarray:
    n = float(np.hypot(*v))
    return v if n <= limit else v * (limit / n)
