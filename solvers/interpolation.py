"""Bilinear interpolation in a 2-D nodal array at a fractional index, over the
finite corners of the cell only.

An infinite node (blocked, not reached by a front, not known yet) drops out
and the other corners' weights are renormalised, so a value or a gradient
read next to an obstacle or the edge of a front stays finite. Arrays are
indexed ``[ix, iy]``; a fractional index ``(px, py)`` is in nodes from the
first one.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["bilinear", "finite_corners"]


@numba.njit(cache=True)
def finite_corners(a, px, py):
    """The cell of ``a`` holding ``(px, py)``, clamped into the array, as its
    lowest node ``(i, j)``, and the bilinear weights of its corners ``(i, j)``,
    ``(i, j + 1)``, ``(i + 1, j)``, ``(i + 1, j + 1)``: 0 for an infinite
    corner, so corner ``k`` is ``a[i + k // 2, j + k % 2]`` where its weight
    is positive."""
    nx, ny = a.shape
    px = min(max(px, 0.0), nx - 1.0)
    py = min(max(py, 0.0), ny - 1.0)
    i = min(int(math.floor(px)), nx - 2)
    j = min(int(math.floor(py)), ny - 2)
    fx = px - i
    fy = py - j
    w00 = (1.0 - fx) * (1.0 - fy)
    w01 = (1.0 - fx) * fy
    w10 = fx * (1.0 - fy)
    w11 = fx * fy
    return (
        i,
        j,
        (
            w00 if w00 > 0.0 and a[i, j] < np.inf else 0.0,
            w01 if w01 > 0.0 and a[i, j + 1] < np.inf else 0.0,
            w10 if w10 > 0.0 and a[i + 1, j] < np.inf else 0.0,
            w11 if w11 > 0.0 and a[i + 1, j + 1] < np.inf else 0.0,
        ),
    )


@numba.njit(cache=True)
def bilinear(a, px, py):
    """The value of ``a`` at ``(px, py)`` from the finite corners of its cell,
    their weights renormalised; infinity where none of weight is finite."""
    i, j, w = finite_corners(a, px, py)
    num = 0.0
    den = 0.0
    for k in range(4):
        if w[k] > 0.0:
            num += w[k] * a[i + k // 2, j + k % 2]
            den += w[k]
    if den == 0.0:
        return np.inf
    return num / den
