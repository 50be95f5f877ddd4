"""Time the sweeping solver of the time to win (``solvers.sweeping``)
against the time marcher (``solvers.levelset.hji``, first order and WENO5)
on the open-square flag return, with each one's set against the exact one.

    python benchmarks/sweeping.py               # 21^4 and 31^4
    python benchmarks/sweeping.py --sizes 25 45

Per solver and size: seconds, node updates per node (the sweeps' worked
nodes; the marcher's node time steps, each of one Euler step or three
Runge-Kutta stages), nanoseconds per node update, and the share of nodes
whose sign differs from the set geometry gives
(``tests.support.flag_return``). The last column is the sweep's time over
each marcher's. Each solve runs once after a warm-up at 11^4, so compile
time is left out; the machine is shared, so the node updates say more than
the seconds.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.support, from a checkout

from bearcat.solvers.levelset.hamiltonians import SimpleMotion
from bearcat.solvers.levelset.hji import solve_reach_avoid
from bearcat.solvers.sweeping.game import solve_time_to_win
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[21, 31], help="nodes per axis (default 21 31)")
    sizes = parser.parse_args().sizes
    march(11, "first"), march(11, "weno5"), sweep(11)  # compile, or load numba's cache
    print(f"{'n':>4} {'solver':<14} {'s':>8} {'updates/node':>13} {'ns/update':>10} {'wrong %':>8} {'sweep/this':>11}")
    for n in sizes:
        g, _, _ = open_square(n, RADIUS)
        exact = flag_return_by_geometry(g, RADIUS)
        rows = {"sweep": sweep(n), "march first": march(n, "first"), "march weno5": march(n, "weno5")}
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
