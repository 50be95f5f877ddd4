"""The quadrotor backflip of thesis 6.1.3: its modes, their sets and the
checks that make the flip safe by design.

The six states of eq. 6.3 split as the thesis splits them. The attitude
``(phi, phi')`` carries attainability: the impulse (the D-DD law) spins the
vehicle up into ``T1``, the motors spin down (eq. 6.6, a linear decay of
the thrust's angular acceleration at rate ``alpha``), the vehicle drifts
with the motors off into ``T2``, and the recovery's PD brings it to hover in
``T3``. The height ``(y, y')`` carries safety: ``K3`` is where the recovery
must never be (the ground, or falling too fast for the height), ``K2`` where
it must not start, ``K1`` where the drift must not start; the impulse is
taken to lose no height (its thrust points up), so it shares ``K1``, and a
climb before it lifts the vehicle out of ``K1``.

Capture sets ``RA_T(T_k)`` come from the target of the last mode backwards
(6.1.3); the turn-off's forward reach from ``T1`` is a 3-D set in
``(phi, phi', a)``, ``a`` the thrust's remaining angular acceleration, and
is projected onto the attitude plane. Avoid sets go backwards from ``K3``.
The recovery couples height to attitude through the thrust's direction, so
its avoid set is taken in ``(y, y', tau)``, ``tau`` the time since the
recovery began, and the rotors' vertical thrust bounded at each ``tau`` by
its envelope over recovery paths from ``T2`` (the thesis's nominal
trajectory with bounds on its deviation).

Where the thesis gives a horizon only as "the longest the mode can take",
it is computed from the attitude dynamics: the drift's as the longest
time-to-reach of ``T2`` from the states the impulse hands over, with the
turn-off and the drift as one 3-D system in ``(phi, phi', a)``; the
recovery's as the longest time-to-reach of its capture set over ``T2``.
The height counts the drift, turn-off included, as a free fall: the
decaying thrust points mostly up while the motors spin down, and what it
gives is left out.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numba
import numpy as np

from bearcat.solvers.errors import InputError, fraction, positive
from bearcat.solvers.grid import Grid
from bearcat.solvers.levelset.hamiltonians import Box, ControlAffine
from bearcat.solvers.levelset.hji import ReachAvoidResult
from bearcat.solvers.maneuvers.planar_quad import (
    DRIFT,
    IMPULSE,
    RECOVERY,
    Laws,
    Quadrotor,
    rotational_acceleration,
    thrust_acceleration,
    thrusts,
)
from bearcat.solvers.maneuvers.sets import (
    Containment,
    Mode,
    avoid_set,
    box,
    capture_sequence,
    capture_set,
    forward_reach,
)

__all__ = ["Backflip", "BackflipSets", "SetProgress", "TargetBox", "design"]

SetProgress = Callable[[str, float, float, float], None]
"""``progress(set name, t, horizon, change)``, called as each set is solved."""


@dataclass(frozen=True)
class TargetBox:
    """A box in the attitude plane, in radians and radians per second."""

    angle: tuple[float, float]
    rate: tuple[float, float]

    def __post_init__(self) -> None:
        if not (self.angle[0] < self.angle[1] and self.rate[0] < self.rate[1]):
            raise InputError(f"a target box needs lo < hi on both axes, got {self.angle} and {self.rate}")

    def value(self, grid: Grid) -> np.ndarray:
        return box(grid, (self.angle[0], self.rate[0]), (self.angle[1], self.rate[1]))

    def holds(self, phi: float, rate: float) -> bool:
        return self.angle[0] <= phi <= self.angle[1] and self.rate[0] <= rate <= self.rate[1]


@dataclass(frozen=True)
class Backflip:
    """Every number the backflip's design depends on.

    Disturbances (eq. 6.4) come from thrust noise: in a powered mode it is
    ``thrust_noise`` times the mode's nominal collective thrust, in the drift
    ``drift_noise`` times the weight. It pushes the height and the sideways
    position in full; only the share ``torque_share`` of it that differs
    between the two sides turns the vehicle (``1`` is the worst case, one
    side's noise against the other's)."""

    vehicle: Quadrotor
    laws: Laws
    thrust_noise: float
    drift_noise: float
    torque_share: float
    spin_down_time: float
    start: TargetBox
    t1: TargetBox
    t2: TargetBox
    t3: TargetBox
    impulse_horizon: float
    drift_horizon: float
    recovery_horizon: float
    fall_rate: float
    attitude_grid: Grid
    vertical_grid: Grid
    spin_down_points: int = 15
    recovery_time_points: int = 21

    def __post_init__(self) -> None:
        for name in ("spin_down_time", "impulse_horizon", "drift_horizon", "recovery_horizon", "fall_rate"):
            positive(getattr(self, name), name.replace("_", " "))
        for name in ("thrust_noise", "drift_noise", "torque_share"):
            fraction(getattr(self, name), name.replace("_", " "))
        if self.attitude_grid.ndim != 2 or self.vertical_grid.ndim != 2:
            raise InputError("the attitude and vertical grids must be 2-D")

    def lift(self, mode: int) -> float:
        laws = self.laws
        return {IMPULSE: laws.impulse_lift, RECOVERY: laws.recovery_lift}.get(mode, laws.climb_lift)

    def force_bound(self, mode: int) -> float:
        """The largest thrust-noise acceleration (m/s^2) in ``mode``."""
        g = self.vehicle.gravity
        return self.drift_noise * g if mode == DRIFT else self.thrust_noise * self.lift(mode) * g

    def torque_bound(self, mode: int) -> float:
        """The largest disturbing angular acceleration (rad/s^2) in ``mode``."""
        v = self.vehicle
        return self.torque_share * self.force_bound(mode) * v.mass * v.arm / v.inertia

    def disturbance(self, mode: int) -> np.ndarray:
        """``(d_x, d_y, d_phi)`` bounds of eq. 6.4 in ``mode``."""
        f = self.force_bound(mode)
        return np.array([f, f, self.torque_bound(mode)])


@dataclass(frozen=True)
class BackflipSets:
    """The solved design. Attitude sets lie on ``design.attitude_grid``,
    height sets on ``design.vertical_grid``; every value is ``<= 0`` inside.

    ``capture`` holds ``RA_T(T_k)`` by mode, ``reach`` the turn-off's forward
    reach ``Reach_T4(T1)``, ``unsafe`` the sets ``K1``-``K3`` at the entry of
    the drift, the recovery and (``K3``) during the recovery. ``checks`` are
    the sequencing conditions in flight order. ``turn_off`` is the range of
    the thrust's angular acceleration when the impulse hands over, ``alpha``
    the rate (rad/s^3) at which eq. 6.6 decays it, and ``times`` the
    horizons the sets used."""

    design: Backflip
    capture: dict[str, ReachAvoidResult]
    reach: np.ndarray
    unsafe: dict[str, np.ndarray]
    checks: list[Containment]
    turn_off: tuple[float, float]
    alpha: float
    times: dict[str, float]
    lift_envelope: np.ndarray = field(repr=False)

    @property
    def holds(self) -> bool:
        return all(check.holds for check in self.checks)


def design(
    backflip: Backflip, *, progress: SetProgress | None = None, scheme: str = "weno5", device: str = "auto"
) -> BackflipSets:
    """Solve every set of the backflip and check the sequence, on ``device``
    (``solve_reach_avoid``'s)."""
    grid = backflip.attitude_grid
    solver = {"scheme": scheme, "tol": 0.0, "device": device}

    def solved(name, horizon, solve, **kw):
        tick = None if progress is None else (lambda t, change: progress(name, t, horizon, change))
        return solve(horizon=horizon, progress=tick, **solver, **kw)

    turn_off = handover_acceleration(backflip)
    spin_down_time = backflip.spin_down_time
    alpha = -turn_off[0] / spin_down_time
    reach_grid, reach_start = _turn_off_start(backflip, turn_off)
    reach = solved(
        "Reach_T4(T1)",
        spin_down_time,
        lambda **kw: forward_reach(reach_grid, _turn_off(backflip, alpha), reach_start, **kw),
    ).value.min(axis=2)
    modes = [
        Mode("impulse", _attitude(backflip, IMPULSE), backflip.t1.value(grid), "T1", backflip.impulse_horizon),
        Mode("drift", _attitude(backflip, DRIFT), backflip.t2.value(grid), "T2", backflip.drift_horizon),
        Mode("recovery", _attitude(backflip, RECOVERY), backflip.t3.value(grid), "T3", backflip.recovery_horizon),
    ]
    sequence = capture_sequence(
        grid,
        modes,
        start=("the hover box (where the climb hands over)", backflip.start.value(grid)),
        handovers={"impulse": ("Reach_T4(T1) (the turn-off's forward reach)", reach)},
        progress=progress,
        record_tstar=True,
        **solver,
    )
    rec = sequence.capture["recovery"]
    handed_over = solved(
        "drift time",
        spin_down_time + backflip.drift_horizon,
        lambda **kw: capture_set(
            reach_grid,
            _turn_off(backflip, alpha),
            np.repeat(backflip.t2.value(grid)[:, :, None], reach_grid.shape[2], 2),
            record_tstar=True,
            **kw,
        ),
    )
    assert handed_over.tstar is not None and rec.tstar is not None  # both solved with record_tstar
    drift_time = _longest(handed_over.tstar, reach_start <= 0, spin_down_time + backflip.drift_horizon)
    recovery_time = _longest(rec.tstar, backflip.t2.value(grid) <= 0, backflip.recovery_horizon)
    envelope = lift_envelope(backflip, recovery_time)
    vertical = backflip.vertical_grid
    k3 = ground_set(backflip, vertical)
    rec_grid = Grid.spanning(
        (*vertical.lo, 0.0), (*vertical.hi, recovery_time), (*vertical.shape, backflip.recovery_time_points)
    )
    k2 = solved(
        "K2",
        recovery_time,
        lambda **kw: avoid_set(
            rec_grid,
            _recovery_height(backflip, envelope, recovery_time),
            np.repeat(k3[:, :, None], rec_grid.shape[2], 2),
            **kw,
        ),
    ).value[:, :, 0]
    k1 = solved("K1", drift_time, lambda **kw: avoid_set(vertical, _drift_height(backflip), k2, **kw)).value
    return BackflipSets(
        backflip,
        sequence.capture,
        reach,
        {"K1": k1, "K2": k2, "K3": k3},
        sequence.checks,
        turn_off,
        alpha,
        {
            "impulse": backflip.impulse_horizon,
            "turn-off": spin_down_time,
            "drift": drift_time,
            "recovery": recovery_time,
        },
        envelope,
    )


def ground_set(backflip: Backflip, grid: Grid) -> np.ndarray:
    """``K3`` (6.1.3): the ground ``y <= 0`` and the falls ``y' <= -k y``
    that hit it in about ``1/k`` s; each edge's function is a distance."""
    y, v = grid.mesh()
    k = backflip.fall_rate
    return np.minimum(y, (v + k * y) / math.hypot(1.0, k))


def handover_acceleration(backflip: Backflip) -> tuple[float, float]:
    """The range of the thrust's angular acceleration (rad/s^2) the impulse
    leaves over ``T1``: where the turn-off of eq. 6.6 starts its decay."""
    quad, laws = backflip.vehicle.array(), backflip.laws.array()
    phis = np.linspace(*backflip.t1.angle, 41)
    rates = np.linspace(*backflip.t1.rate, 41)
    values = [_thrust_acc(p, r, quad, laws) for p in phis for r in rates]
    lo, hi = min(values), min(max(values), 0.0)
    if lo >= 0:
        raise InputError("the impulse leaves no turning thrust over T1: there is nothing for the motors to spin down")
    return lo, hi


def lift_envelope(backflip: Backflip, horizon: float, samples: int = 9) -> np.ndarray:
    """``(times, lowest, highest)`` of the vertical thrust over the weight
    along recovery paths from ``T2`` (a ``samples`` x ``samples`` lattice)
    under the constant disturbances ``-D, 0, D``: the bounds that decouple
    the recovery's height from its attitude."""
    quad, laws = backflip.vehicle.array(), backflip.laws.array()
    times = np.linspace(0.0, horizon, backflip.recovery_time_points)
    bound = backflip.torque_bound(RECOVERY)
    starts = [(p, r) for p in np.linspace(*backflip.t2.angle, samples) for r in np.linspace(*backflip.t2.rate, samples)]
    paths = np.array([_recovery_lift(p, r, d, times, quad, laws) for p, r in starts for d in (-bound, 0.0, bound)])
    return np.stack([times, paths.min(axis=0), paths.max(axis=0)])


def _longest(tstar: np.ndarray, where: np.ndarray, horizon: float) -> float:
    """The longest time-to-reach over ``where``; the whole ``horizon`` if some
    of it never reaches (a failed check says so; safety then assumes the worst)."""
    times = tstar[where]
    if times.size == 0 or not np.isfinite(times).all():
        return horizon
    return float(times.max())


def _turn_off_start(backflip: Backflip, turn_off: tuple[float, float]) -> tuple[Grid, np.ndarray]:
    """The 3-D grid of the turn-off, ``(phi, phi', a)``, and on it the states
    the impulse hands over: ``T1``, each point with the acceleration the
    impulse's law leaves there (to within a cell of ``a``)."""
    grid = backflip.attitude_grid
    lo, hi = turn_off
    margin = 0.1 * (hi - lo) + 0.05 * (-lo)
    g3 = Grid.spanning((*grid.lo, lo - margin), (*grid.hi, margin), (*grid.shape, backflip.spin_down_points))
    quad, laws = backflip.vehicle.array(), backflip.laws.array()
    phi, rate = grid.mesh()
    left = _handover_field(phi.ravel(), rate.ravel(), quad, laws).reshape(grid.shape)
    a = g3.axes()[2]
    near = np.abs(a[None, None, :] - left[:, :, None]) / g3.spacing[2] - 1.0
    return g3, np.maximum(backflip.t1.value(grid)[:, :, None], near)


def _attitude(backflip: Backflip, mode: int) -> ControlAffine:
    """The closed loop of ``mode`` in ``(phi, phi')`` with its disturbance (eq. 6.2)."""
    quad, laws = backflip.vehicle.array(), backflip.laws.array()

    @numba.njit
    def closed_loop(x, f0, G, K):  # pragma: no cover - compiled
        f0[0] = x[1]
        f0[1] = rotational_acceleration(mode, x[0], x[1], quad, laws)
        K[0, 0] = 0.0
        K[1, 0] = 1.0

    bound = backflip.torque_bound(mode)
    return ControlAffine(closed_loop, disturbance=Box((-bound,), (bound,)))


def _turn_off(backflip: Backflip, alpha: float) -> ControlAffine:
    """Eq. 6.6 in ``(phi, phi', a)``: the motors' angular acceleration ``a``
    decays linearly at ``alpha`` to zero while the vehicle turns, with the
    drift's disturbance."""
    drag = backflip.vehicle.rotational_drag / backflip.vehicle.inertia

    @numba.njit
    def spinning_down(x, f0, G, K):  # pragma: no cover - compiled
        f0[0] = x[1]
        f0[1] = x[2] - drag * x[1]
        f0[2] = alpha if x[2] < 0.0 else 0.0
        K[0, 0] = 0.0
        K[1, 0] = 1.0
        K[2, 0] = 0.0

    bound = backflip.torque_bound(DRIFT)
    return ControlAffine(spinning_down, disturbance=Box((-bound,), (bound,)))


def _drift_height(backflip: Backflip) -> ControlAffine:
    """Height with the motors off: free fall, drag and the drift's noise."""
    v = backflip.vehicle
    g, drag = v.gravity, v.translational_drag / v.mass

    @numba.njit
    def falling(x, f0, G, K):  # pragma: no cover - compiled
        f0[0] = x[1]
        f0[1] = -g - drag * x[1]
        K[0, 0] = 0.0
        K[1, 0] = 1.0

    bound = backflip.force_bound(DRIFT)
    return ControlAffine(falling, disturbance=Box((-bound,), (bound,)))


def _recovery_height(backflip: Backflip, envelope: np.ndarray, horizon: float) -> ControlAffine:
    """Height in the recovery in ``(y, y', tau)``: the rotors' vertical
    thrust lies in its envelope at ``tau``; the disturbance picks it, and
    the thrust noise, against the vehicle."""
    v = backflip.vehicle
    g, drag = v.gravity, v.translational_drag / v.mass
    lift = g
    times, lowest, highest = (np.ascontiguousarray(row) for row in envelope)
    last = len(times) - 1
    step = horizon / last

    @numba.njit
    def recovering(x, f0, G, K):  # pragma: no cover - compiled
        s = min(max(x[2] / step, 0.0), float(last))
        i = min(int(s), last - 1)
        w = s - i
        lo = (1 - w) * lowest[i] + w * lowest[i + 1]
        hi = (1 - w) * highest[i] + w * highest[i + 1]
        f0[0] = x[1]
        f0[1] = lift * (lo + hi) / 2 - g - drag * x[1]
        f0[2] = 1.0
        K[0, 0] = 0.0
        K[0, 1] = 0.0
        K[1, 0] = 1.0
        K[1, 1] = lift * (hi - lo) / 2
        K[2, 0] = 0.0
        K[2, 1] = 0.0

    bound = backflip.force_bound(RECOVERY)
    return ControlAffine(recovering, disturbance=Box((-bound, -1.0), (bound, 1.0)))


@numba.njit(cache=True)
def _thrust_acc(phi, rate, quad, laws):
    t1, t2 = thrusts(IMPULSE, phi, rate, quad, laws)
    return thrust_acceleration(t1, t2, quad)


@numba.njit(cache=True)
def _handover_field(phis, rates, quad, laws):
    out = np.empty(phis.shape[0])
    for k in range(phis.shape[0]):
        out[k] = min(_thrust_acc(phis[k], rates[k], quad, laws), 0.0)
    return out


@numba.njit(cache=True)
def _recovery_lift(phi, rate, d, times, quad, laws):
    """The rotors' vertical thrust over the weight at ``times`` along the
    recovery from ``(phi, rate)`` under a constant ``d``."""
    out = np.empty(times.shape[0])
    dt = 1e-3
    t = 0.0
    for k in range(times.shape[0]):
        while t < times[k] - 1e-12:
            h = min(dt, times[k] - t)
            a1 = rotational_acceleration(RECOVERY, phi, rate, quad, laws) + d
            p2, r2 = phi + 0.5 * h * rate, rate + 0.5 * h * a1
            a2 = rotational_acceleration(RECOVERY, p2, r2, quad, laws) + d
            phi, rate = phi + h * r2, rate + h * a2
            t += h
        t1, t2 = thrusts(RECOVERY, phi, rate, quad, laws)
        out[k] = (t1 + t2) * math.cos(phi) / (quad[0] * quad[1])
    return out
