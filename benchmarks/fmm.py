"""Time bearcat's fast marching against scikit-fmm, the campus open-loop solve,
and the first call in a fresh process.

    python benchmarks/fmm.py

Needs scikit-fmm (``pip install -e ".[bench]"``). Prints one table per part.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time

import numpy as np
import skfmm

from bearcat.solvers.grid import Grid
from bearcat.solvers.marching.fmm import point_source, travel_time
from bearcat.solvers.marching.openloop import Defender, solve_openloop

REPEATS = {400: 9, 1000: 5, 2000: 3}


def median_seconds(fn, repeats: int) -> float:
    fn()  # warm-up (and compile)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def obstacle_field(n: int):
    """A square of n x n nodes at 1 m: three buildings and a slow zone."""
    g = Grid.covering((0.0, 0.0), (n - 1.0, n - 1.0), 1.0)
    x, y = g.mesh()
    speed = np.ones(g.shape)
    speed[(x > 0.6 * n) & (x < 0.8 * n) & (y > 0.2 * n) & (y < 0.5 * n)] = 0.3
    for x0, x1, y0, y1 in ((0.30, 0.35, 0.0, 0.7), (0.50, 0.55, 0.4, 1.0), (0.15, 0.25, 0.8, 0.9)):
        speed[(x > x0 * n) & (x < x1 * n) & (y > y0 * n) & (y < y1 * n)] = 0.0
    return g, speed, (0.1 * n + 0.3, 0.5 * n + 0.2)


def part_a() -> None:
    print("(a) plain fast marching, first order, point source, obstacles and a slow zone")
    print(f"{'grid':>10} {'bearcat ms':>11} {'skfmm ms':>9} {'speed-up':>9} {'max |diff| s':>13}")
    for n in REPEATS:
        g, speed, src = obstacle_field(n)
        initial = point_source(g, src, speed)
        ours_s = median_seconds(lambda speed=speed, initial=initial: travel_time(speed, 1.0, initial), REPEATS[n])
        ours = travel_time(speed, 1.0, initial)
        # scikit-fmm starts from the zero level set of phi (a small circle
        # around the source) and takes obstacles as a mask.
        x, y = g.mesh()
        r0 = 1.5
        phi = np.ma.MaskedArray(np.hypot(x - src[0], y - src[1]) - r0, speed == 0)
        v = np.ma.MaskedArray(np.where(speed > 0, speed, 1.0), speed == 0)
        theirs_s = median_seconds(lambda phi=phi, v=v: skfmm.travel_time(phi, v, 1.0, order=1), REPEATS[n])
        theirs = np.ma.filled(skfmm.travel_time(phi, v, 1.0, order=1), np.inf)
        theirs = np.where(np.hypot(x - src[0], y - src[1]) < r0, np.inf, theirs + r0)
        both = np.isfinite(ours) & np.isfinite(theirs)
        diff = np.abs(ours[both] - theirs[both]).max()
        print(f"{n:>5}^2    {ours_s * 1e3:>11.1f} {theirs_s * 1e3:>9.1f} {theirs_s / ours_s:>8.2f}x {diff:>13.3f}")


def campus_game():
    from bearcat.maps import load_map, rasterize

    raster = rasterize(load_map("campus-400"), 1.0)
    m = raster.speed
    defenders = [Defender((330.0, 120.0), 1.0 * m, 2.0), Defender((200.0, 250.0), 0.5 * m, 2.0)]
    args = (raster.grid, (30.0, 30.0), [5.0 * m, 2.0 * m], [raster.masks["flag"], raster.masks["home"]], defenders)
    return raster, args


def part_b() -> None:
    raster, args = campus_game()
    solution = solve_openloop(*args)
    seconds = median_seconds(lambda: solve_openloop(*args), 15)
    print()
    print("(b) campus-400 at 1 m: two defenders (1x, 0.5x terrain, r_c 2 m), two stages (5x, 2x), with path")
    print(f"{'grid':>10} {'median ms':>10}   result")
    values = ", ".join(f"stage {k + 1} {s.value:.1f} s" for k, s in enumerate(solution.stages))
    length = np.hypot(*np.diff(solution.path.points, axis=0).T).sum() if solution.path is not None else 0.0
    shape = "x".join(str(n) for n in raster.grid.shape)
    print(f"{shape:>10} {seconds * 1e3:>10.1f}   {values}; path {length:.0f} m, {len(solution.path.points)} vertices")


FIRST_CALL = textwrap.dedent(
    """
    import time
    t = time.perf_counter()
    import numpy as np
    from bearcat.solvers.grid import Grid
    from bearcat.solvers.marching.openloop import Defender, solve_openloop
    g = Grid.covering((0, 0), (30, 30), 0.5)
    v = np.ones(g.shape)
    x, y = g.mesh()
    target = np.hypot(x - 25, y - 25) < 2
    s = solve_openloop(g, (3.0, 3.0), [2 * v, 2 * v], [target, np.hypot(x - 4, y - 4) < 2],
                       [Defender((28.0, 8.0), 0.5 * v, 1.0), Defender((10.0, 28.0), 0.5 * v, 1.0)])
    assert s.path is not None
    print(time.perf_counter() - t)
    """
)


def fresh_process(env: dict) -> float:
    out = subprocess.run([sys.executable, "-c", FIRST_CALL], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip())


def part_c() -> None:
    print()
    print("(c) first solve in a fresh process (imports + one small two-stage, two-defender solve with path)")
    env = dict(os.environ)
    fresh_process(env)  # make sure the user's cache holds every kernel
    warm = fresh_process(env)
    with tempfile.TemporaryDirectory() as cache:
        cold = fresh_process({**env, "NUMBA_CACHE_DIR": cache})
    print(f"{'numba cache':>12} {'seconds':>8}")
    print(f"{'warm':>12} {warm:>8.2f}")
    print(f"{'cold':>12} {cold:>8.2f}   (compiles every kernel)")


if __name__ == "__main__":
    part_a()
    part_b()
    part_c()
