"""Geodesics from a source on a speed map: where they run straight, and the
direction in which each leaves the source.

A geodesic is the straight segment wherever the segment keeps the source's
speed all along. Elsewhere (behind a corner, across a change of speed) the
direction it leaves in is carried from node to node along the fast marching
front: ``e`` is constant along every ray, so upwind transport in arrival
order keeps the constant that a ray bending round a corner takes, where
plain upwind transport from the source smears it by up to 18 degrees on a
100 x 100 grid.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from bearcat.solvers.interpolation import bilinear

__all__ = ["first_steps", "sees"]


@numba.njit(cache=True)
def sees(speed, v0, hx, hy, px, py, qx, qy):
    """Whether the segment from ``p`` to ``q`` (metres from the first node)
    stays on nodes of speed ``v0``, sampled every half spacing: there the
    geodesic is the segment itself."""
    nx, ny = speed.shape
    dist = math.hypot(qx - px, qy - py)
    n = int(dist / (0.5 * min(hx, hy))) + 1
    for q in range(1, n + 1):
        t = q / n
        i = min(max(int(math.floor((px + t * (qx - px)) / hx + 0.5)), 0), nx - 1)
        j = min(max(int(math.floor((py + t * (qy - py)) / hy + 0.5)), 0), ny - 1)
        if speed[i, j] != v0:
            return False
    return True


@numba.njit(cache=True, error_model="numpy")
def first_steps(psi, speed, hx, hy, sx, sy, v0, limit):
    """Unit direction ``e`` in which the geodesic from the source (``sx, sy``
    metres from the first node) to each node leaves the source.

    Nodes are visited in arrival order. A node is *seen* when it has the
    source's speed and the point one spacing back toward the source lies among
    seen nodes (bilinear weight of seen corners above one half, blocked
    corners counting as unseen): there the geodesic is the straight segment
    and ``e`` is the direction to the node. Elsewhere ``e`` is the upwind
    average of the neighbours it arrives from, weighted as the eikonal update
    weights them, which carries ``e`` along the rays.
    """
    nx, ny = psi.shape
    out = np.zeros((nx, ny, 2))
    seen = np.zeros((nx, ny))  # 1 seen, 0 unseen or blocked, infinity not visited yet
    for i in range(nx):
        for j in range(ny):
            if speed[i, j] > 0 and psi[i, j] <= limit:
                seen[i, j] = np.inf
    order = _sorted_nodes(psi, limit)
    step = min(hx, hy)
    near = 1.01 * math.hypot(hx, hy)
    for k in order:
        i = k // ny
        j = k - i * ny
        dx = i * hx - sx
        dy = j * hy - sy
        r = math.hypot(dx, dy)
        visible = False
        if speed[i, j] == v0:
            if r <= near:
                visible = True
            else:
                # The share of seen corners around the point one step back, among the visited ones.
                share = bilinear(seen, (i * hx - step * dx / r) / hx, (j * hy - step * dy / r) / hy)
                visible = 0.5 < share < np.inf
        if visible:
            seen[i, j] = 1.0
            if r > 0.0:
                out[i, j, 0] = dx / r
                out[i, j, 1] = dy / r
            continue
        seen[i, j] = 0.0
        wx, ui = _upwind(psi, i, j, 1, 0, hx)
        wy, uj = _upwind(psi, i, j, 0, 1, hy)
        ex = 0.0
        ey = 0.0
        if wx > 0.0:
            ex += wx * out[ui, j, 0]
            ey += wx * out[ui, j, 1]
        if wy > 0.0:
            ex += wy * out[i, uj, 0]
            ey += wy * out[i, uj, 1]
        norm = math.hypot(ex, ey)
        if norm > 0.0:
            out[i, j, 0] = ex / norm
            out[i, j, 1] = ey / norm
        elif r > 0.0:
            out[i, j, 0] = dx / r
            out[i, j, 1] = dy / r
    return out


@numba.njit(cache=True)
def _upwind(psi, i, j, di, dj, h):
    """The weight the eikonal update gives the earlier neighbour of node
    ``(i, j)`` along axis ``(di, dj)`` (0 if neither arrived earlier), and
    that neighbour's index along the axis."""
    n = psi.shape[0] if di else psi.shape[1]
    k = i if di else j
    lo = psi[i - di, j - dj] if k > 0 else np.inf
    hi = psi[i + di, j + dj] if k < n - 1 else np.inf
    b = min(lo, hi)
    if b < psi[i, j]:
        return (psi[i, j] - b) / (h * h), k - 1 if lo <= hi else k + 1
    return 0.0, k


@numba.njit(cache=True)
def _sorted_nodes(values, limit):
    """Flat indices of the finite entries ``<= limit`` in increasing order: a
    counting sort on twice as many buckets as entries, then insertion sort
    within buckets."""
    flat = values.ravel()
    limit = min(limit, np.finfo(np.float64).max)
    n = 0
    top = 0.0
    for k in range(flat.size):
        v = flat[k]
        if v <= limit:
            n += 1
            top = max(top, v)
    idx = np.empty(n, dtype=np.int64)
    if n == 0:
        return idx
    nb = 2 * n
    scale = (nb - 1) / top if top > 0 else 0.0
    start = np.zeros(nb + 1, dtype=np.int64)
    for k in range(flat.size):
        v = flat[k]
        if v <= limit:
            start[int(v * scale) + 1] += 1
    for b in range(nb):
        start[b + 1] += start[b]
    for k in range(flat.size):
        v = flat[k]
        if v <= limit:
            b = int(v * scale)
            idx[start[b]] = k
            start[b] += 1
    for a in range(1, n):
        k = idx[a]
        v = flat[k]
        b = a - 1
        while b >= 0 and flat[idx[b]] > v:
            idx[b + 1] = idx[b]
            b -= 1
        idx[b + 1] = k
    return idx
