"""Bilinear interpolation in a 2-D nodal array at a fractional index, over the
finite corners of the cell only.

An infinite node (blocked, not reached by a front, not known yet) drops out
and the other corners' weights are renormalised, so a value or a gradient
read next to an obstacle or the edge of a front stays finite. Arrays are
indexed ``[ix, iy]``; a fractional index ``(px, py)`` is in nodes from the
first one, clamped into the array.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["bilinear", "upwind_gradient"]


@numba.njit(cache=True)
def bilinear(a, px, py):
    """The value of ``a`` at ``(px, py)`` from the finite corners of its cell,
    their weights renormalised; infinity where none of weight is finite."""
    value, _, _ = _blend(a, px, py, 1.0, 1.0, False)
    return value


@numba.njit(cache=True)
def upwind_gradient(a, px, py, hx, hy):
    """The gradient of ``a`` at ``(px, py)`` for node spacings ``hx, hy``:
    each finite corner's difference toward its lower finite neighbour on each
    axis (0 at a minimum), blended with the weights of ``bilinear``; zero
    where no corner is finite. Upwind differences of a value function point
    down its characteristics, where central ones would straddle a kink."""
    _, gx, gy = _blend(a, px, py, hx, hy, True)
    return gx, gy


@numba.njit(cache=True, inline="always")
def _blend(a, px, py, hx, hy, gradient):
    nx, ny = a.shape
    px = min(max(px, 0.0), nx - 1.0)
    py = min(max(py, 0.0), ny - 1.0)
    i = min(int(math.floor(px)), nx - 2)
    j = min(int(math.floor(py)), ny - 2)
    fx = px - i
    fy = py - j
    num = 0.0
    gx = 0.0
    gy = 0.0
    den = 0.0
    for u in range(2):
        for v in range(2):
            w = (fx if u else 1.0 - fx) * (fy if v else 1.0 - fy)
            c = a[i + u, j + v]
            if w > 0.0 and c < np.inf:
                num += w * c
                if gradient:
                    gx += w * _upwind(c, a, i + u, j + v, 1, 0) / hx
                    gy += w * _upwind(c, a, i + u, j + v, 0, 1) / hy
                den += w
    if den == 0.0:
        return np.inf, 0.0, 0.0
    return num / den, gx / den, gy / den


@numba.njit(cache=True, inline="always")
def _upwind(c, a, i, j, di, dj):
    """Difference toward the lower finite neighbour along one axis (0 at a minimum)."""
    nx, ny = a.shape
    lo = a[i - di, j - dj] if i - di >= 0 and j - dj >= 0 else np.inf
    hi = a[i + di, j + dj] if i + di < nx and j + dj < ny else np.inf
    if lo <= hi:
        return c - lo if lo < c else 0.0
    return hi - c if hi < c else 0.0
