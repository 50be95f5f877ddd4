"""Time robust capture-the-flag answers (solvers/ctf/robust.py) on the
fake-out's 45^4 game against the plain query, and against a worst case found
by sampling each disk and interpolating the value with scipy.

    python benchmarks/robust.py           # 200 states per row
    python benchmarks/robust.py --quick   # 40 states per row

Rows are the disks a ground station meets: a fresh exact fix; phones
reporting once a second under wifi (3 m/s players, fixes up to a second and a
half old, the 95 % circle of a 1.96 m GPS error per axis); the same with the
GPS error left out (``guidance.confidence = 0``); and fixes one to three
seconds old, as over 3G. The sampled worst case
uses 64 points per disk (4096 pairs, one vectorised interpolation); it can
only miss the worst case, by the "misses" column (metres of value: the
smallest, the median and the largest), where ours bounds it by construction.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

SPEED = 3.0
ROWS = {
    "fresh, exact": lambda rng: 0.0,
    "wifi, 1 Hz": lambda rng: SPEED * rng.uniform(0.1, 1.5) + 2.448 * 1.96,
    "wifi, 1 Hz, age only": lambda rng: SPEED * rng.uniform(0.1, 1.5),
    "3g, 1-3 s old": lambda rng: SPEED * rng.uniform(1.0, 3.0) + 2.448 * 1.96,
}
SAMPLES = 64


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="40 states per row")
    args = parser.parse_args()
    from scipy.interpolate import RegularGridInterpolator

    from bearcat.scenarios.cast import _CtfGame
    from bearcat.scenarios.schema import load_scenario
    from bearcat.solvers.ctf.queries import interpolate_2d
    from bearcat.solvers.ctf.robust import RobustCtf
    from bearcat.solvers.ctf.sets import EDGE_SLACK

    queries = _CtfGame(load_scenario("fake-out")).solved()
    robust = RobustCtf(queries)
    grid = queries.geometry.grid
    value = queries.value_set("return").value
    g = queries.geometry
    forfeits = np.minimum(np.minimum(g.flag, g.home), g.blocked)

    def allowed(point) -> bool:
        return interpolate_2d(forfeits, np.array(grid.lo), np.array(grid.spacing), point) >= -EDGE_SLACK * min(
            grid.spacing
        )

    sampled = RegularGridInterpolator(queries.solution.grid.axes(), value)
    rng = np.random.default_rng(1)
    states = 40 if args.quick else 200
    print(
        f"robust queries on the fake-out's {grid.shape[0]}^4 game (field-50, return stage), medians over {states} "
        "random states; ms per display (both covers, worst case, heading) and for its region"
    )
    print(
        f"{'disks':<22} {'radius m':>8} {'plain ms':>9} {'robust ms':>10} {'region ms':>10} {'sampled ms':>11} "
        f"{'vs sampled':>10} {'misses m (min, median, max)':>28}"
    )
    lo, hi = np.array(grid.lo) + 1.0, np.array(grid.hi) - 6.0  # clear of the return strip
    for name, radius_of in ROWS.items():
        times = {"plain": [], "robust": [], "region": [], "sampled": []}
        misses, radii = [], []
        centres = [p for p in rng.uniform(lo, hi, size=(4 * (states + 5), 2)) if allowed(p)]
        for k in range(states + 5):
            a, d = rng.uniform(lo, hi), centres.pop()
            ra, rd = radius_of(rng), radius_of(rng)
            t0 = time.perf_counter()
            queries.evaluate(a, d, "return")
            t1 = time.perf_counter()
            covers = robust.cover("attacker", a, ra), robust.cover("defender", d, rd)
            worst = robust.answer("attacker", *covers, "return").worst
            t2 = time.perf_counter()
            robust.region_values("defender", covers[0], "return")
            t3 = time.perf_counter()
            pa, pd = _disk_points(rng, a, ra, grid), _disk_points(rng, d, rd, grid)
            pd = pd[[allowed(p) for p in pd]]  # a defender forfeits in the flag or the return strip
            pairs = np.concatenate([np.repeat(pa, len(pd), axis=0), np.tile(pd, (len(pa), 1))], axis=1)
            found = float(np.max(sampled(pairs)))
            t4 = time.perf_counter()
            if k >= 5:  # the first calls load compiled code
                for key, dt in zip(times, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
                    times[key].append(1e3 * dt)
                misses.append(worst - found)
                radii.append(ra)
        m = {key: float(np.median(v)) for key, v in times.items()}
        print(
            f"{name:<22} {np.median(radii):>8.1f} {m['plain']:>9.3f} {m['robust']:>10.3f} {m['region']:>10.3f} "
            f"{m['sampled']:>11.3f} {m['sampled'] / m['robust']:>9.1f}x "
            f"{np.min(misses):>8.3f}, {np.median(misses):>7.3f}, {np.max(misses):>7.3f}",
            flush=True,
        )
    print("misses: how far the sampled worst case fell short of ours; a negative one would be a state ours missed")


def _disk_points(rng, centre, radius, grid) -> np.ndarray:
    """``SAMPLES`` points spread over the disk (its centre first), clipped to the grid."""
    r = radius * np.sqrt(rng.uniform(size=SAMPLES - 1))
    t = rng.uniform(0, 2 * np.pi, SAMPLES - 1)
    points = np.vstack([centre, centre + np.stack([r * np.cos(t), r * np.sin(t)], axis=1)])
    return np.clip(points, grid.lo, grid.hi)


if __name__ == "__main__":
    main()
