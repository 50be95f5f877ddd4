"""Time the sweeping solver of the time to win (``solvers.sweeping``)
against the time marcher (``solvers.levelset.hji``, first order and WENO5)
on the open-square flag return, with each one's set against the exact one;
and, as the scheme the sweeps could have used instead of Godunov's, the
Lax-Friedrichs sweeping of Kao, Osher and Qian (2004), written here for
the reach-avoid value alone, serial.

    python benchmarks/sweeping.py               # 21^4 and 31^4
    python benchmarks/sweeping.py --sizes 25 45

Per solver and size: seconds, node updates per node (the sweeps' worked
nodes; the marcher's node time steps, each of one Euler step or three
Runge-Kutta stages), nanoseconds per node update, and the share of nodes
whose sign differs from the set geometry gives
(``tests.support.flag_return``). The last column is the sweep's time over
each marcher's. Each solve runs once after a warm-up at 11^4, so compile
time is left out; the machine is shared, so the node updates say more than
the seconds. The Lax-Friedrichs row solves ``V`` only (its set is
``{V <= 0}``; ``T*`` would cost as much again), on one thread.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.support, from a checkout

from bearcat.solvers.levelset.hamiltonians import SimpleMotion
from bearcat.solvers.levelset.hji import solve_reach_avoid
from bearcat.solvers.sweeping import kernels
from bearcat.solvers.sweeping.game import DEFAULT_TOL, MAX_ROUNDS, solve_time_to_win
from tests.support.flag_return import flag_return_by_geometry, open_square

RADIUS = 1.5
HORIZON = 16.0  # s: past the longest time to win in the square, so the marcher runs to its fixed point


def march(n: int, scheme: str):
    g, target, avoid = open_square(n, RADIUS)
    began = time.perf_counter()
    result = solve_reach_avoid(g, SimpleMotion.pursuit(1.0, 1.0), target, avoid, horizon=HORIZON, scheme=scheme)
    stages = 3 if scheme == "weno5" else 1
    return time.perf_counter() - began, result.node_updates * stages, result.reach_avoid_set


def sweep(n: int):
    g, target, avoid = open_square(n, RADIUS)
    ones = np.ones((n, n))
    began = time.perf_counter()
    result = solve_time_to_win(g.spacing, ones, ones, target, avoid, ceiling=4 * HORIZON)
    return time.perf_counter() - began, result.node_updates, result.value <= 0


@njit(cache=True)
def _around(u, node, stride, i, n, rising):
    """The neighbours of ``node`` along one axis; beyond an edge, the edge's
    slope mirrored, rising for the attacker's axes and falling for the
    defender's, so that leaving helps neither (``levelset.kernels._beyond``)."""
    if 0 < i < n - 1:
        return u[node - stride], u[node + stride]
    inner = u[node + stride] if i == 0 else u[node - stride]
    ghost = u[node] + abs(u[node] - inner) if rising else u[node] - abs(u[node] - inner)
    return (ghost, inner) if i == 0 else (inner, ghost)


@njit(cache=True)
def _lax_friedrichs_sweep(u, target, avoid, speed, h, order):
    """One Gauss-Seidel sweep of ``v |grad_a V| - v |grad_d V| = 0`` with
    the Lax-Friedrichs numerical Hamiltonian: central differences, and
    dissipation ``speed`` on every axis, which makes each node's update
    explicit: the mean of its eight neighbours less ``H(central) h / 4
    speed``, kept between ``l`` and ``-g`` and never raised, as the Godunov
    sweep keeps it. The largest change."""
    n0, n1, n2, n3 = u.shape
    s0, s1, s2 = n1 * n2 * n3, n2 * n3, n3
    flat, low, high = u.reshape(-1), target.reshape(-1), avoid.reshape(-1)
    worst = 0.0
    for j0 in range(n0):
        i0 = j0 if order[0] > 0 else n0 - 1 - j0
        for j1 in range(n1):
            i1 = j1 if order[1] > 0 else n1 - 1 - j1
            for j2 in range(n2):
                i2 = j2 if order[2] > 0 else n2 - 1 - j2
                for j3 in range(n3):
                    i3 = j3 if order[3] > 0 else n3 - 1 - j3
                    node = i0 * s0 + i1 * s1 + i2 * s2 + i3
                    a0, a1 = _around(flat, node, s0, i0, n0, True)
                    a2, a3 = _around(flat, node, s1, i1, n1, True)
                    b0, b1 = _around(flat, node, s2, i2, n2, False)
                    b2, b3 = _around(flat, node, 1, i3, n3, False)
                    hamiltonian = speed * (math.hypot(a1 - a0, a3 - a2) - math.hypot(b1 - b0, b3 - b2)) / (2 * h)
                    mean = (a0 + a1 + a2 + a3 + b0 + b1 + b2 + b3) / 8
                    root = mean - hamiltonian * h / (4 * speed)
                    old = flat[node]
                    new = max(-high[node], min(low[node], root, old))
                    worst = max(worst, old - new)
                    flat[node] = new
    return worst


def lax_friedrichs(n: int):
    g, target, avoid = open_square(n, RADIUS)
    target, avoid = (np.ascontiguousarray(a, np.float64) for a in (target, avoid))
    value = np.maximum(target, -avoid)
    h = float(g.spacing[0])
    began = time.perf_counter()
    sweeps = 0
    for _ in range(MAX_ROUNDS * 10):
        change = 0.0
        for order in kernels.ORDERS:
            change = max(change, _lax_friedrichs_sweep(value, target, avoid, 1.0, h, order))
            sweeps += 1
        if change <= DEFAULT_TOL * h:
            break
    return time.perf_counter() - began, sweeps * g.size, value <= 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[21, 31], help="nodes per axis (default 21 31)")
    sizes = parser.parse_args().sizes
    march(11, "first"), march(11, "weno5"), sweep(11), lax_friedrichs(11)  # compile, or load numba's cache
    print(f"{'n':>4} {'solver':<14} {'s':>8} {'updates/node':>13} {'ns/update':>10} {'wrong %':>8} {'sweep/this':>11}")
    for n in sizes:
        g, _, _ = open_square(n, RADIUS)
        exact = flag_return_by_geometry(g, RADIUS)
        rows = {
            "sweep": sweep(n),
            "march first": march(n, "first"),
            "march weno5": march(n, "weno5"),
            "sweep LF, V": lax_friedrichs(n),
        }
        swept = rows["sweep"][0]
        for name, (seconds, updates, found) in rows.items():
            wrong = 100 * np.mean(found != exact)
            per = 1e9 * seconds / updates
            print(
                f"{n:>4} {name:<14} {seconds:8.2f} {updates / g.size:13.0f} {per:10.1f} {wrong:8.2f} "
                f"{swept / seconds:11.2f}"
            )


if __name__ == "__main__":
    main()
