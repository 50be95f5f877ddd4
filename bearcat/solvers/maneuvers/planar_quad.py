"""The planar quadrotor of thesis eq. 6.3 and the fixed control laws of its
backflip (6.1.3), as compiled functions of plain arrays.

One model serves two users: the reach sets of ``solvers.maneuvers.backflip`` fold a
mode's law into its dynamics (eq. 6.2), and the flight simulator of
``solvers.maneuvers.backflip_flight`` integrates the full six-state model with the
same laws. Keeping both on these functions is what makes the simulated
flips a test of the sets rather than of a second model.

Angles are radians, the attitude ``phi`` grows counter-clockwise, and the
flip turns clockwise from ``phi = 2 pi`` (hover before the flip) down to
``phi = 0`` (hover after it), so no angle wraps. The two thrusts act as in
eq. 6.3: ``T2 - T1`` turns the vehicle, ``T1 + T2`` lifts it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from bearcat.solvers.errors import InputError, positive

__all__ = ["Laws", "Quadrotor"]


@dataclass(frozen=True)
class Quadrotor:
    """The constants of eq. 6.3: mass (kg), gravity (m/s^2), the linear
    translational and rotational drag coefficients, the moment of inertia
    (kg m^2), the arm from the centre to a rotor (m) and the largest thrust
    one side's rotors give (N, eq. 6.5)."""

    mass: float
    gravity: float
    translational_drag: float
    rotational_drag: float
    inertia: float
    arm: float
    max_thrust: float

    def __post_init__(self) -> None:
        for name in ("mass", "gravity", "inertia", "arm", "max_thrust"):
            positive(getattr(self, name), f"vehicle {name}")
        if self.translational_drag < 0 or self.rotational_drag < 0:
            raise InputError("vehicle drag coefficients must be >= 0")
        if 2 * self.max_thrust <= self.weight:
            raise InputError(
                f"a vehicle whose two sides give at most {2 * self.max_thrust:g} N cannot lift its {self.weight:g} N"
            )

    @property
    def weight(self) -> float:
        return self.mass * self.gravity

    def array(self) -> np.ndarray:
        """The constants in the order the compiled functions index them (``Q_*``)."""
        return np.array(
            [
                self.mass,
                self.gravity,
                self.translational_drag,
                self.rotational_drag,
                self.inertia,
                self.arm,
                self.max_thrust,
            ]
        )


Q_MASS, Q_GRAVITY, Q_DRAG, Q_ROT_DRAG, Q_INERTIA, Q_ARM, Q_MAX_THRUST = range(7)


@dataclass(frozen=True)
class Laws:
    """The fixed control laws of the powered modes (eq. 6.1), each a
    differential thrust from the attitude state and a collective thrust as a
    multiple of the weight.

    - impulse, the D-DD law: it tracks the rate schedule of a constant
      angular acceleration ``impulse_acceleration`` from hover, feeding that
      acceleration forward (the double derivative) and the rate error back
      with gain ``impulse_rate_gain`` (the derivative);
    - recovery (and the attitude hold of the climb): PD on ``phi`` towards 0
      (towards ``2 pi`` in the climb), gains ``recovery_angle_gain`` (1/s^2)
      and ``recovery_rate_gain`` (1/s). Its collective follows the
      attitude, ``recovery_lift * cos phi`` of the weight but never below
      ``recovery_floor``: full lift once upright, and while the vehicle is
      still upside down only what the turn needs, so the rotors do not
      drive it into the ground.

    Both cancel the rotational drag they know of, and the thrusts saturate
    at ``[0, F_max]`` (eq. 6.5), so what a law asks and what the rotors give
    differ once a command is large."""

    impulse_acceleration: float
    impulse_rate_gain: float
    impulse_lift: float
    recovery_angle_gain: float
    recovery_rate_gain: float
    recovery_lift: float
    recovery_floor: float
    climb_lift: float

    def __post_init__(self) -> None:
        for name in ("impulse_acceleration", "impulse_rate_gain", "recovery_angle_gain", "recovery_rate_gain"):
            positive(getattr(self, name), f"control law {name}")
        for name in ("impulse_lift", "recovery_lift", "recovery_floor", "climb_lift"):
            positive(getattr(self, name), f"control law {name}")

    def array(self) -> np.ndarray:
        """The gains in the order the compiled functions index them (``L_*``)."""
        return np.array(
            [
                self.impulse_acceleration,
                self.impulse_rate_gain,
                self.impulse_lift,
                self.recovery_angle_gain,
                self.recovery_rate_gain,
                self.recovery_lift,
                self.recovery_floor,
                self.climb_lift,
            ]
        )


L_IMPULSE_ACC, L_IMPULSE_GAIN, L_IMPULSE_LIFT, L_REC_ANGLE, L_REC_RATE, L_REC_LIFT, L_REC_FLOOR, L_CLIMB_LIFT = range(8)

CLIMB, IMPULSE, DRIFT, RECOVERY = range(4)
"""Mode numbers, in flight order."""

TWO_PI = 2.0 * math.pi


@numba.njit(cache=True)
def split(collective, differential, max_thrust):
    """Rotor thrusts ``(T1, T2)`` for a collective ``T1 + T2`` and a
    differential ``T2 - T1``, each clipped to ``[0, max_thrust]``."""
    t1 = min(max((collective - differential) / 2.0, 0.0), max_thrust)
    t2 = min(max((collective + differential) / 2.0, 0.0), max_thrust)
    return t1, t2


@numba.njit(cache=True)
def commanded_acceleration(mode, phi, rate, laws):
    """The angular acceleration ``mode``'s law asks for at ``(phi, rate)``."""
    if mode == IMPULSE:
        a = laws[L_IMPULSE_ACC]
        left = max(TWO_PI - phi, 0.0)
        reference = -math.sqrt(2.0 * a * left)
        return -a + laws[L_IMPULSE_GAIN] * (reference - rate)
    target = TWO_PI if mode == CLIMB else 0.0
    return -laws[L_REC_ANGLE] * (phi - target) - laws[L_REC_RATE] * rate


@numba.njit(cache=True)
def collective_share(mode, phi, laws):
    """The collective thrust ``mode``'s law asks for, over the weight."""
    if mode == IMPULSE:
        return laws[L_IMPULSE_LIFT]
    if mode == CLIMB:
        return laws[L_CLIMB_LIFT]
    return max(laws[L_REC_LIFT] * math.cos(phi), laws[L_REC_FLOOR])


@numba.njit(cache=True)
def thrusts(mode, phi, rate, quad, laws):
    """``(T1, T2)`` that ``mode``'s law gives at ``(phi, rate)``: the
    differential that yields its angular acceleration with the rotational
    drag cancelled, on the mode's collective, saturated (eq. 6.5)."""
    weight = quad[Q_MASS] * quad[Q_GRAVITY]
    wanted = commanded_acceleration(mode, phi, rate, laws)
    differential = (quad[Q_INERTIA] * wanted + quad[Q_ROT_DRAG] * rate) / quad[Q_ARM]
    return split(collective_share(mode, phi, laws) * weight, differential, quad[Q_MAX_THRUST])


@numba.njit(cache=True)
def thrust_acceleration(t1, t2, quad):
    """The angular acceleration the rotors' thrusts give (the last column of eq. 6.3)."""
    return quad[Q_ARM] * (t2 - t1) / quad[Q_INERTIA]


@numba.njit(cache=True)
def rotational_acceleration(mode, phi, rate, quad, laws):
    """``phi''`` of the closed loop of a powered ``mode`` without disturbance,
    or of the drift (motors off) for ``mode == DRIFT``."""
    drag = -quad[Q_ROT_DRAG] * rate / quad[Q_INERTIA]
    if mode == DRIFT:
        return drag
    t1, t2 = thrusts(mode, phi, rate, quad, laws)
    return drag + thrust_acceleration(t1, t2, quad)


@numba.njit(cache=True)
def planar(state, t1, t2, disturbance, quad, out):
    """Eq. 6.3: ``out`` = the derivative of ``(x, x', y, y', phi, phi')`` under
    rotor thrusts ``t1, t2`` and disturbance ``(d_x, d_y, d_phi)``."""
    m, g, cv, cphi, inertia, arm = quad[0], quad[1], quad[2], quad[3], quad[4], quad[5]
    total = t1 + t2
    s, c = math.sin(state[4]), math.cos(state[4])
    out[0] = state[1]
    out[1] = -cv * state[1] / m + disturbance[0] - s * total / m
    out[2] = state[3]
    out[3] = -(m * g + cv * state[3]) / m + disturbance[1] + c * total / m
    out[4] = state[5]
    out[5] = -cphi * state[5] / inertia + disturbance[2] + arm * (t2 - t1) / inertia
