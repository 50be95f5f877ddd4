"""Maneuver sets (thesis 6.1): capture, avoid and forward-reach sets of the
HJI solver on small grids, against analytic sets, and the sequencing check."""

import math

import numba
import numpy as np

from bearcat.solvers.grid import Grid
from bearcat.solvers.levelset.hamiltonians import Box, ControlAffine
from bearcat.solvers.maneuvers.sets import Mode, avoid_set, box, capture_sequence, capture_set, contained, forward_reach


@numba.njit(cache=True)
def double_integrator(x, f0, G, K):
    """x1' = x2, x2' = u."""
    f0[0] = x[1]
    f0[1] = 0.0
    G[0, 0] = 0.0
    G[1, 0] = 1.0


@numba.njit(cache=True)
def falling(x, f0, G, K):
    """y' = v, v' = -1 + d: a body in free fall pushed by a bounded disturbance."""
    f0[0] = x[1]
    f0[1] = -1.0
    K[0, 0] = 0.0
    K[1, 0] = 1.0


def minimum_time(x1, x2):
    """Time for x1'' = u, |u| <= 1 to reach the origin (bang-bang, one switch)."""
    above = x1 > -x2 * np.abs(x2) / 2
    return np.where(
        above, x2 + 2 * np.sqrt(np.maximum(x1 + x2**2 / 2, 0)), -x2 + 2 * np.sqrt(np.maximum(-x1 + x2**2 / 2, 0))
    )


GRID = Grid.spanning((-2.0, -2.0), (2.0, 2.0), (101, 101))
HALF = 0.05  # the target box's half-width around the origin


def test_a_double_integrators_capture_set_lies_between_the_analytic_minimum_time_sets():
    """Reaching the box B within T lies between reaching the origin within T and
    within T + tau, tau the longest time from a point of B to the origin."""
    horizon = 1.5
    dynamics = ControlAffine(double_integrator, control=Box((-1.0,), (1.0,)))
    found = capture_set(GRID, dynamics, box(GRID, (-HALF, -HALF), (HALF, HALF)), horizon, tol=0).reach_avoid_set
    x1, x2 = GRID.mesh()
    tstar = minimum_time(x1, x2)
    tau = float(minimum_time(np.array(HALF), np.array(HALF)))
    slack = 0.1  # s: a few cells of the scheme's smearing at these speeds
    assert found[tstar <= horizon - slack].all()
    assert not found[tstar >= horizon + tau + slack].any()
    assert (tstar <= horizon).sum() < found.sum() < (tstar <= horizon + tau).sum()


def test_a_falling_bodys_avoid_set_is_where_the_worst_push_grounds_it():
    """y'' = -1 + d, |d| <= 0.5: the worst push is d = -0.5, so the body
    reaches y <= 0 within T from (y, v) iff y + v t - 0.75 t^2 <= 0 for some t <= T."""
    grid = Grid.spanning((-0.5, -3.0), (4.0, 3.0), (91, 121))
    y, v = grid.mesh()
    horizon = 1.0
    dynamics = ControlAffine(falling, disturbance=Box((-0.5,), (0.5,)))
    found = avoid_set(grid, dynamics, y, horizon, tol=0).reach_avoid_set
    t = np.linspace(0, horizon, 401)[:, None, None]
    lowest = (y + v * t - 0.75 * t**2).min(axis=0)
    # Where the worst push would carry the state out of the grid (below v = -3)
    # before it lands, the solver's edge rule counts it safe: leaving the grid
    # never helps the side reaching for the set. Compare where it stays inside.
    kept = v - 1.5 * horizon >= grid.lo[1]
    wrong = (found != (lowest <= 0)) & kept
    assert np.abs(lowest[wrong]).max(initial=0.0) < 3 * grid.spacing[0]
    assert found[(lowest < -0.1) & kept].all() and ((lowest <= 0) & kept).sum() > 1000


def test_a_forward_reach_holds_every_state_the_disturbance_can_lead_to():
    """From the box around (2, 0), y'' = -1 + d, |d| <= 0.5, for 0.8 s: every
    simulated path stays inside the forward reach (to within a cell), which
    does not spread below the strongest pull's reach."""
    grid = Grid.spanning((-0.5, -3.0), (4.0, 3.0), (91, 121))
    dynamics = ControlAffine(falling, disturbance=Box((-0.5,), (0.5,)))
    start = box(grid, (1.9, -0.1), (2.1, 0.1))
    reach = forward_reach(grid, dynamics, start, 0.8, tol=0)
    rng = np.random.default_rng(0)
    for _ in range(40):
        y, v = rng.uniform(1.9, 2.1), rng.uniform(-0.1, 0.1)
        for _ in range(80):  # 0.8 s in steps of 0.01 s, a new push every step
            d = rng.choice([-0.5, 0.5])
            y, v = y + 0.01 * v, v + 0.01 * (-1 + d)
            i, j = round((y + 0.5) / grid.spacing[0]), round((v + 3.0) / grid.spacing[1])
            assert reach.value[i - 1 : i + 2, j - 1 : j + 2].min() <= 0, (y, v)  # in the set, to a cell
    y, v = grid.mesh()
    assert not reach.reach_avoid_set[v < -0.1 - 1.5 * 0.8 - 0.1].any()


def test_a_sequence_whose_next_capture_set_misses_part_of_a_target_says_which_and_by_how_much():
    capture = capture_set(
        GRID,
        ControlAffine(double_integrator, control=Box((-1.0,), (1.0,))),
        box(GRID, (-HALF, -HALF), (HALF, HALF)),
        1.0,
        tol=0,
    ).value
    inside = contained(box(GRID, (-0.1, -0.1), (0.1, 0.1)), capture, ("T_a", "RA(T_b)"))  # T* <= 0.75 s on it
    assert inside.holds and inside.worst <= 0 and "T_a lies inside RA(T_b)" in str(inside)
    outside = contained(box(GRID, (1.0, -0.2), (1.8, 0.2)), capture, ("T_drift", "RA(T_recovery)"))
    assert not outside.holds and 0 < outside.outside <= 1 and outside.worst > 0
    assert str(outside).startswith("T_drift is not inside RA(T_recovery)")
    assert math.isfinite(outside.worst)


def test_a_sequence_solves_from_the_last_mode_back_and_names_the_modes_whose_hand_over_fails():
    """Two modes of the same double integrator: ``approach`` hands over in a
    box around (1, 0), ``settle`` must take it to the origin. With 3 s,
    settling reaches the origin from all of that box (T* <= 2.2 s there);
    with 1 s it cannot, and the check says which modes and by how much."""
    dynamics = ControlAffine(double_integrator, control=Box((-1.0,), (1.0,)))
    handover = box(GRID, (0.9, -0.1), (1.1, 0.1))
    origin = box(GRID, (-HALF, -HALF), (HALF, HALF))
    start = ("the start", box(GRID, (1.4, -0.1), (1.6, 0.1)))
    seen = []

    def sequence(settle_time):
        modes = [
            Mode("approach", dynamics, handover, "T_a", 2.0),
            Mode("settle", dynamics, origin, "T_s", settle_time),
        ]
        return capture_sequence(GRID, modes, start=start, progress=lambda *a: seen.append(a[0]), tol=0)

    held = sequence(3.0)
    assert held.holds and not held.failures()
    assert seen[0] == "RA_T(T_s)" and seen[-1] == "RA_T(T_a)"  # the last mode is solved first
    failed = sequence(1.0)
    assert [str(c).split(":")[0] for c in failed.failures()] == [
        "T_a (the approach's target) is not inside RA_T(T_s) (the settle's capture set)"
    ]
    assert failed.checks[0].holds and failed.failures()[0].outside == 1.0
