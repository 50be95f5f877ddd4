"""The flag-return stage of capture-the-flag in an open square, with the
set geometry gives: the reference both the time marcher's and the sweeping
solver's sets are held to (``tests.test_hji``, ``tests.test_sweeping``,
``benchmarks/sweeping.py``). Each player's plane is ``[-5, 5]^2``; the
attacker must reach the strip ``x >= 4`` without coming within the capture
radius of the defender, who forfeits by entering it; both at speed 1."""

import math

import numba
import numpy as np
from scipy import ndimage

from bearcat.solvers.grid import Grid
from bearcat.solvers.levelset.hamiltonians import SimpleMotion
from bearcat.solvers.levelset.hji import solve_reach_avoid

STRIP = 4.0  # the return strip x >= 4 along the edge x = 5


@numba.njit(cache=True)
def _margin(ax, ay, dx, dy, samples):
    """min over y in the strip [4, 5] x [-5, 5] of |y - a| - |y - d|.
    The difference of distances has no critical point off the ray from the
    attacker away from the defender, where it takes its global minimum
    -|a - d|; otherwise the minimum lies on the strip's boundary, sampled
    and then refined by golden section."""
    sep = math.hypot(ax - dx, ay - dy)
    if ax > dx:
        y = ay + (STRIP - ax) * (ay - dy) / (ax - dx)
        if -5.0 <= y <= 5.0:
            return -sep
    corners = ((STRIP, -5.0), (STRIP, 5.0), (5.0, 5.0), (5.0, -5.0), (STRIP, -5.0))
    best = np.inf
    for e in range(4):
        x0, y0 = corners[e]
        x1, y1 = corners[e + 1]
        k_best, f_best = 0, np.inf
        for k in range(samples + 1):
            s = k / samples
            px, py = x0 + s * (x1 - x0), y0 + s * (y1 - y0)
            f = math.hypot(px - ax, py - ay) - math.hypot(px - dx, py - dy)
            if f < f_best:
                k_best, f_best = k, f
        lo, hi = max(0.0, (k_best - 1) / samples), min(1.0, (k_best + 1) / samples)
        for _ in range(40):
            m1, m2 = lo + 0.382 * (hi - lo), lo + 0.618 * (hi - lo)
            f1 = math.hypot(x0 + m1 * (x1 - x0) - ax, y0 + m1 * (y1 - y0) - ay) - math.hypot(
                x0 + m1 * (x1 - x0) - dx, y0 + m1 * (y1 - y0) - dy
            )
            f2 = math.hypot(x0 + m2 * (x1 - x0) - ax, y0 + m2 * (y1 - y0) - ay) - math.hypot(
                x0 + m2 * (x1 - x0) - dx, y0 + m2 * (y1 - y0) - dy
            )
            if f1 < f2:
                hi = m2
            else:
                lo = m1
            f_best = min(f_best, f1, f2)
        best = min(best, f_best)
    return best


@numba.njit(cache=True)
def _flag_return_by_geometry(axis, capture_radius):
    n = axis.shape[0]
    out = np.zeros((n, n, n, n), np.bool_)
    for i0 in range(n):
        for i1 in range(n):
            for i2 in range(n):
                for i3 in range(n):
                    ax, ay, dx, dy = axis[i0], axis[i1], axis[i2], axis[i3]
                    if math.hypot(ax - dx, ay - dy) <= capture_radius:
                        continue
                    if ax >= STRIP or dx >= STRIP:
                        out[i0, i1, i2, i3] = True
                    else:
                        out[i0, i1, i2, i3] = _margin(ax, ay, dx, dy, 100) < -capture_radius
    return out


def flag_return_by_geometry(grid, capture_radius):
    """With equal speeds the attacker wins iff it is not captured now and
    some point y of the strip has |y - x_a| + r_c < |y - x_d|: the straight
    run to y stays in that (convex) region, where the defender cannot come
    within r_c in time; otherwise the defender holds the dominance boundary.
    This stays exact with the defender barred from the strip and both kept
    in the square because the square, and the square less the strip, are
    convex: the defender's straight interceptions never need to leave
    them."""
    return _flag_return_by_geometry(grid.axes()[0], capture_radius)


def open_square(n, capture_radius):
    """The grid, target ``l`` and avoid ``g`` of the flag return at ``n^4`` nodes."""
    g = Grid.spanning((-5.0,) * 4, (5.0,) * 4, (n,) * 4)
    xa, ya, xd, yd = np.meshgrid(*g.axes(), indexing="ij", sparse=True)
    target = np.broadcast_to(np.minimum(STRIP - xa, STRIP - xd), g.shape)
    avoid = np.broadcast_to(np.hypot(xa - xd, ya - yd) - capture_radius, g.shape)
    return g, target, avoid


def flag_return(n, scheme, capture_radius):
    """The time marcher's set at ``n^4`` nodes, by ``scheme``."""
    g, target, avoid = open_square(n, capture_radius)
    result = solve_reach_avoid(g, SimpleMotion.pursuit(1.0, 1.0), target, avoid, horizon=16.0, scheme=scheme)
    return g, result.reach_avoid_set


def far_from_boundary(mask, cells):
    """Nodes more than ``cells`` node spacings from any node of the other class."""
    inside = ndimage.distance_transform_edt(mask)
    outside = ndimage.distance_transform_edt(~mask)
    return np.where(mask, inside, outside) > cells
