"""Time one control step of safe-reachable-area pursuit (thesis 5.2.2) on the
thesis's non-convex domains at 0.1 m (101 x 101 nodes).

    python benchmarks/pursuit_fmm.py [--repeats N]

A control step is ``FmmAreaPursuit.headings`` for a new state: the evader and
every pursuer stand somewhere they did not stand before, so no front is in
the travel times' cache. The thesis took about 100 ms per pursuer (Matlab, 2012);
the aim is under 5 ms for three pursuers. Also timed: pure pursuit
along the geodesic, and a whole game step: the farthest-point evader picks a
new target (forced every step, the dearer case), then the pursuers' headings
on the same travel times reuse the fronts and the safe set it computed.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from bearcat.maps import load_map, rasterize
from bearcat.solvers.pursuit.fmm import FarthestPointEvader, FmmAreaPursuit, GeodesicPursuit, TravelTimes

MAPS = ("triangle-10", "maze-10")
SPACING = 0.1


def states(raster, n_pursuers: int, count: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """``count`` random states on free nodes, shifted off the nodes, agents at least 1.5 m apart."""
    rng = np.random.default_rng(seed)
    nodes = np.argwhere(raster.free)
    out = []
    while len(out) < count:
        picked = nodes[rng.choice(len(nodes), n_pursuers + 1, replace=False)]
        pts = np.asarray(raster.grid.lo) + picked * SPACING
        pts = np.clip(pts + rng.uniform(-0.03, 0.03, pts.shape), 0.0, 10.0)
        gaps = np.hypot(*(pts[:, None] - pts[None]).reshape(-1, 2).T)
        if np.sort(gaps)[len(pts)] >= 1.5:  # the smallest gap between distinct agents
            out.append((pts[0], pts[1:]))
    return out


def median_ms(step, cases) -> tuple[float, float]:
    step(*cases[0])  # warm-up: load or compile the numba kernels
    times = []
    for e, ps in cases[1:]:
        t = time.perf_counter()
        step(e, ps)
        times.append(time.perf_counter() - t)
    times.sort()
    return statistics.median(times) * 1e3, times[int(0.9 * (len(times) - 1))] * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=60, help="states timed per row (default 60)")
    args = parser.parse_args()
    print("one control step, fresh positions every time; milliseconds, median (90th percentile)")
    print(f"{'map':<12} {'N':>2} {'boundary':>16} {'finite':>16} {'geodesic':>16} {'game step':>16}")
    for name in MAPS:
        raster = rasterize(load_map(name), SPACING)
        for n in (1, 2, 3):
            cases = states(raster, n, args.repeats + 1, seed=n)
            row = []
            for gradient in ("boundary", "finite"):
                strategy = FmmAreaPursuit(TravelTimes(raster.grid, raster.speed), gradient=gradient)
                row.append(median_ms(strategy.headings, cases))
            row.append(median_ms(GeodesicPursuit(TravelTimes(raster.grid, raster.speed)).headings, cases))
            travel_times = TravelTimes(raster.grid, raster.speed)
            pursuit, evader = FmmAreaPursuit(travel_times), FarthestPointEvader(travel_times)

            def game_step(e, ps, evader=evader, pursuit=pursuit):
                evader.target = None  # a fresh target every step: the dearer case
                evader.heading(e, ps)
                pursuit.headings(e, ps)

            row.append(median_ms(game_step, cases))
            cells = " ".join(f"{m:>8.2f} ({p:>5.2f})" for m, p in row)
            print(f"{name:<12} {n:>2} {cells}")


if __name__ == "__main__":
    main()
