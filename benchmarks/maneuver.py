"""Time the backflip's 2-D sets (thesis 6.1) in bearcat's HJI solver against
hj_reachability, each on the same grid, horizon, closed loop, scheme (WENO5 +
TVD-RK3), CFL number and edge rule.

    python benchmarks/maneuver.py           # the built-in backflip's grids
    python benchmarks/maneuver.py --quick   # grids halved, a few seconds a set

Needs ``pip install -e ".[bench]"`` (JAX on the CPU). The sets are the three
capture sets ``RA_T(T_k)`` in the attitude plane and the drift's unsafe set
``K1`` in the height plane (``K2`` lives in 3-D and the turn-off in 3-D, so
they are left out). Both solvers are warmed up on a small grid first (numba's
cache load, JAX's compilation), so the seconds are solving only. The closed
loops are written twice, once as bearcat's compiled laws and once in
``jax.numpy`` below; the ``differ`` column (the share of nodes whose
membership the two solvers disagree on) is the check that they match.

hj_reachability gets the same update as bearcat's capture set, ``min(V, l)``
after every step (the monotone clamp of ``solvers.levelset.hji`` is off here, since
hj_reachability has none), and the same ghost extrapolation: values rise
beyond every edge, so leaving the grid never helps the side reaching for the
set.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from dataclasses import replace

import numpy as np


def jax_laws(backflip, mode: str):
    """The closed loop of ``mode`` in ``jax.numpy``, as ``planar_quad`` computes it."""
    import jax.numpy as jnp

    v, law = backflip.vehicle, backflip.laws
    weight, drag = v.mass * v.gravity, v.rotational_drag / v.inertia

    def accelerations(phi, rate):
        if mode == "drift":
            return -drag * rate
        if mode == "impulse":
            a = law.impulse_acceleration
            reference = -jnp.sqrt(2.0 * a * jnp.maximum(2 * math.pi - phi, 0.0))
            wanted = -a + law.impulse_rate_gain * (reference - rate)
            collective = law.impulse_lift * weight
        else:
            wanted = -law.recovery_angle_gain * phi - law.recovery_rate_gain * rate
            collective = jnp.maximum(law.recovery_lift * jnp.cos(phi), law.recovery_floor) * weight
        differential = (v.inertia * wanted + v.rotational_drag * rate) / v.arm
        t1 = jnp.clip((collective - differential) / 2.0, 0.0, v.max_thrust)
        t2 = jnp.clip((collective + differential) / 2.0, 0.0, v.max_thrust)
        return -drag * rate + v.arm * (t2 - t1) / v.inertia

    return accelerations


def run_hj(grid, value_target, drift_of, bound: float, horizon: float, role: str):
    """``min(V, l)`` backwards over ``horizon`` for ``x' = (x1, f(x)) + (0, d)``;
    ``role`` is who ``d`` is: the disturbance (maximises, a capture set) or the
    one reaching for the set (minimises, an avoid set)."""
    import hj_reachability as hj
    import jax.numpy as jnp

    class ClosedLoop(hj.ControlAndDisturbanceAffineDynamics):
        def __init__(self):
            box = hj.sets.Box(jnp.array([-bound]), jnp.array([bound]))
            zero = hj.sets.Box(jnp.array([0.0]), jnp.array([0.0]))
            if role == "disturbance":
                super().__init__("min", "max", zero, box)
            else:
                super().__init__("min", "max", box, zero)

        def open_loop_dynamics(self, state, time):
            return jnp.array([state[1], drift_of(state[0], state[1])])

        def control_jacobian(self, state, time):
            return jnp.array([[0.0], [1.0]])

        def disturbance_jacobian(self, state, time):
            return jnp.array([[0.0], [1.0]])

    up = _rising_edges()
    hj_grid = hj.Grid.from_lattice_parameters_and_boundary_conditions(
        hj.sets.Box(jnp.array(grid.lo), jnp.array(grid.hi)), grid.shape, boundary_conditions=(up, up)
    )
    target = jnp.asarray(value_target, dtype=jnp.float32)
    settings = hj.SolverSettings.with_accuracy("very_high", value_postprocessor=lambda t, v: jnp.minimum(v, target))
    dynamics = ClosedLoop()
    hj.solve(settings, dynamics, hj_grid, jnp.array([0.0, -1e-3]), target, progress_bar=False).block_until_ready()
    start = time.perf_counter()
    values = hj.solve(settings, dynamics, hj_grid, jnp.array([0.0, -horizon]), target, progress_bar=False)
    final = np.asarray(values[-1].block_until_ready())
    return time.perf_counter() - start, final


def _rising_edges():
    import jax.numpy as jnp

    def pad(x, width):
        ramp = jnp.arange(width, 0, -1)
        left = x[0] + jnp.abs(x[1] - x[0]) * ramp
        right = x[-1] + jnp.abs(x[-1] - x[-2]) * ramp[::-1]
        return jnp.concatenate([left, x, right])

    return pad


def run_ours(grid, dynamics, value_target, horizon: float, role: str):
    from bearcat.solvers.maneuvers.sets import avoid_set, capture_set

    solve = capture_set if role == "disturbance" else avoid_set
    small = type(grid).spanning(grid.lo, grid.hi, (9, 9))
    solve(small, dynamics, np.ones(small.shape), 0.01)  # loads the kernels and compiles this closed loop
    start = time.perf_counter()
    result = solve(grid, dynamics, value_target, horizon, tol=0.0, monotone=False)
    return time.perf_counter() - start, result.value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="each grid with half the points per axis")
    args = parser.parse_args()

    from bearcat.scenarios.maneuvers import load_maneuver
    from bearcat.solvers.grid import Grid
    from bearcat.solvers.maneuvers import backflip as bf
    from bearcat.solvers.maneuvers.planar_quad import DRIFT, IMPULSE, RECOVERY

    design = load_maneuver("backflip").design
    if args.quick:
        halve = lambda g: Grid.spanning(g.lo, g.hi, tuple((n - 1) // 2 + 1 for n in g.shape))  # noqa: E731
        design = replace(design, attitude_grid=halve(design.attitude_grid), vertical_grid=halve(design.vertical_grid))
    attitude, vertical = design.attitude_grid, design.vertical_grid
    v = design.vehicle
    cases = [
        ("RA_T(T3) recovery", attitude, RECOVERY, "recovery", design.t3.value(attitude), design.recovery_horizon),
        ("RA_T(T2) drift", attitude, DRIFT, "drift", design.t2.value(attitude), design.drift_horizon),
        ("RA_T(T1) impulse", attitude, IMPULSE, "impulse", design.t1.value(attitude), design.impulse_horizon),
    ]
    print(f"backflip sets, WENO5 + TVD-RK3, float32 (hj_reachability) / float32 (bearcat), {os.cpu_count()} cores")
    print(f"{'set':<20} {'grid':>8} {'horizon':>8} {'bearcat s':>10} {'hj s':>8} {'hj / ours':>10} {'differ':>8}")
    for label, grid, mode, name, target, horizon in cases:
        ours_s, ours = run_ours(grid, bf._attitude(design, mode), target, horizon, "disturbance")
        hj_s, theirs = run_hj(grid, target, jax_laws(design, name), design.torque_bound(mode), horizon, "disturbance")
        _row(label, grid, horizon, ours_s, hj_s, ours, theirs)
    k2_stand_in = bf.ground_set(design, vertical)  # K1 from K3 over the drift: the same 2-D operator as K1 from K2
    fall = lambda y, rate: -v.gravity - v.translational_drag / v.mass * rate  # noqa: E731
    horizon = 1.0
    ours_s, ours = run_ours(vertical, bf._drift_height(design), k2_stand_in, horizon, "reacher")
    hj_s, theirs = run_hj(vertical, k2_stand_in, fall, design.force_bound(DRIFT), horizon, "reacher")
    _row("A_T(K3) drift", vertical, horizon, ours_s, hj_s, ours, theirs)


def _row(label, grid, horizon, ours_s, hj_s, ours, theirs) -> None:
    differ = float(((ours <= 0) != (theirs <= 0)).mean())
    shape = "x".join(str(n) for n in grid.shape)
    print(
        f"{label:<20} {shape:>8} {horizon:>7.2f}s {ours_s:>10.2f} {hj_s:>8.2f} {hj_s / ours_s:>10.2f} "
        f"{100 * differ:>7.2f}%"
    )


if __name__ == "__main__":
    main()
