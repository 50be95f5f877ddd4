"""Time one control step of the convex area-minimising pursuit (thesis
5.2.1) against the same step built on shapely polygon intersection.

    python benchmarks/pursuit_convex.py

One control step is ``area_minimising_headings(domain, evader, pursuers)``:
check the inputs, build the evader's cell, find the lines of control, and
turn Lemma 3's gradient into headings (eq. 5.11, pure pursuit for pursuers
without a line of control). The shapely step does the same with
``Polygon.intersection`` against one half-plane per pursuer, reads each
line of control off the cell's ring, and applies the same formulas; its
headings are compared with ours so that both time the same answer.
``ConvexAreaPursuit.headings``, which checks the domain once up front, is
the step a simulation loop pays.

States are drawn in the 10 x 10 square of thesis 5.3.1 with every pursuer
more than the capture radius (0.5) from the evader. Every call is timed on
its own and the median reported, after a warm-up that loads numba's cache.
"""

from __future__ import annotations

import statistics
import time

import numpy as np
from shapely.geometry import Polygon

from bearcat.solvers.pursuit.convex import ConvexAreaPursuit, area_minimising_headings

SQUARE = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
STATES = 2000
CAPTURE_RADIUS = 0.5


def random_states(n: int, count: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    states = []
    while len(states) < count:
        e = rng.uniform(0, 10, 2)
        p = rng.uniform(0, 10, (n, 2))
        if np.hypot(*(p - e).T).min() > CAPTURE_RADIUS:
            states.append((e, p))
    return states


def shapely_headings(domain: Polygon, evader: np.ndarray, pursuers: np.ndarray) -> np.ndarray:
    """The control step with shapely doing the geometry."""
    cell = domain
    frames = []
    for q in pursuers:
        xi = evader - q
        r = float(np.hypot(*xi))
        eta_h = xi / r
        eta_v = np.array([-eta_h[1], eta_h[0]])
        m = 0.5 * (evader + q)
        reach = 1e3
        cell = cell.intersection(
            Polygon(
                [
                    m + reach * eta_v,
                    m + reach * eta_v + reach * eta_h,
                    m - reach * eta_v + reach * eta_h,
                    m - reach * eta_v,
                ]
            )
        )
        frames.append((r, eta_h, eta_v, m))
    ring = np.asarray(cell.exterior.coords)
    headings = np.empty_like(pursuers)
    for i, (r, eta_h, eta_v, m) in enumerate(frames):
        headings[i] = eta_h
        # The line of control: the edge of the ring lying on the bisector.
        on = np.abs((ring - m) @ eta_h) < 1e-9
        edge = np.flatnonzero(on[:-1] & on[1:])
        if len(edge) == 0:
            continue
        a, b = ring[edge[0]], ring[edge[0] + 1]
        length = float(np.hypot(*(b - a)))
        if length < 1e-11:
            continue
        s = ((a - m) @ eta_v, (b - m) @ eta_v)
        l_i = -min(s)
        alpha_h = -length / 2
        alpha_v = (l_i**2 - (length - l_i) ** 2) / (2 * r)
        g = alpha_h * eta_h + alpha_v * eta_v
        headings[i] = -g / np.hypot(*g)
    return headings


def median_us(fn, states) -> float:
    for e, p in states[:50]:
        fn(e, p)
    times = []
    for e, p in states:
        t = time.perf_counter_ns()
        fn(e, p)
        times.append(time.perf_counter_ns() - t)
    return statistics.median(times) / 1e3


def main() -> None:
    domain = Polygon(SQUARE)
    strategy = ConvexAreaPursuit(SQUARE)
    print(f"one control step, 10 x 10 square, median of {STATES} random states (microseconds)")
    print(f"{'pursuers':>8} {'headings':>9} {'strategy':>9} {'shapely':>8} {'ratio':>7} {'max |diff|':>11}")
    for n in (1, 2, 3):
        states = random_states(n, STATES, seed=n)
        ours = median_us(lambda e, p: area_minimising_headings(SQUARE, e, p), states)
        loop = median_us(strategy.headings, states)
        theirs = median_us(lambda e, p: shapely_headings(domain, e, p), states)
        diff = max(
            np.abs(area_minimising_headings(SQUARE, e, p) - shapely_headings(domain, e, p)).max() for e, p in states
        )
        print(f"{n:>8} {ours:>9.1f} {loop:>9.1f} {theirs:>8.1f} {theirs / ours:>6.1f}x {diff:>11.1e}")
    print("headings: area_minimising_headings; strategy: ConvexAreaPursuit.headings; ratio: shapely / headings")


if __name__ == "__main__":
    main()
