"""Steepest descent through a value function on a 2-D grid: the optimal path
of thesis 4.12 traced backwards, from a start down to where the value was
prescribed (the seeds of a front, or its point source).

Steps follow the gradient of the value interpolated over the finite corners
of each cell (``solvers.interpolation``), so a path never steps into an
obstacle or the unsafe set, where the value is infinite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from bearcat.solvers.errors import InputError, format_point
from bearcat.solvers.grid import Grid
from bearcat.solvers.interpolation import bilinear, upwind_gradient
from bearcat.solvers.marching import fmm

__all__ = ["Descent", "aim_ahead", "compile_kernels", "descend", "descend_steps"]


@dataclass(frozen=True)
class Descent:
    """A steepest-descent path through a value function, from its start downhill.

    ``points`` (n, 2) in metres and ``values`` (n,) the value there, strictly
    decreasing. ``reached`` tells whether it ended on the seeds or source
    rather than at a node it could not descend from.
    """

    points: np.ndarray
    values: np.ndarray
    reached: bool


def descend(grid: Grid, phi, start, *, seeds=None, source=None, steps: int | None = None) -> Descent:
    """Follow ``x' = -grad phi / |grad phi|`` from ``start`` until the seeds.

    This integrates the optimal-path ODE (thesis 4.12) backwards in time.
    ``seeds`` is a boolean mask of nodes where ``phi`` holds its prescribed
    boundary value; the path stops on the first of them it reaches. With
    ``source``, the point ``phi`` was started from by ``fmm.point_source``, the
    path stops on that stencil and ends exactly at ``source`` with value 0.
    With neither, it stops where no neighbour is lower.

    Steps are half the smaller spacing along the interpolated upwind
    gradient. A step that would leave the finite part of ``phi`` or not lower
    the value is replaced by a move to the lowest finite neighbouring node, so
    the path never enters an obstacle or the unsafe set, and ends.

    With ``steps``, the path stops after that many steps, not ``reached``:
    a walker looking a few metres ahead needs only the start of its path,
    which is the start of the whole one, point for point.
    """
    phi = np.ascontiguousarray(phi, dtype=np.float64)
    if phi.shape != grid.shape:
        raise InputError(f"phi has shape {phi.shape} but the grid has shape {grid.shape}")
    if not grid.contains(start):
        raise InputError(f"start point {format_point(start)} lies outside the grid")
    stop = np.zeros(grid.shape, dtype=np.bool_)
    if seeds is not None:
        seeds = np.asarray(seeds, dtype=np.bool_)
        if seeds.shape != grid.shape:
            raise InputError(f"seeds has shape {seeds.shape} but the grid has shape {grid.shape}")
        # The kernel only reads where to stop: the seeds themselves do, unless a source adds to them.
        stop = np.ascontiguousarray(seeds) if source is None else stop | seeds
    if source is not None:
        if not grid.contains(source):
            raise InputError(f"source point {format_point(source)} lies outside the grid")
        ix, iy, _ = fmm.source_stencil(grid, source)
        stop[ix, iy] = True
    hx, hy = grid.spacing
    fi = grid.fractional_index(start)
    limit = 4 * grid.size + 16 if steps is None else min(int(steps), 4 * grid.size + 16)
    xs, ys, vals, status = _descend(phi, stop, float(hx), float(hy), float(fi[0]), float(fi[1]), np.int64(limit))
    if status == _START_INVALID:
        raise InputError(f"start point {format_point(start)} is not on a finite value of phi")
    points = np.asarray(grid.lo) + np.column_stack([xs, ys]) * np.asarray(grid.spacing)
    reached = status == _STOPPED
    if source is not None and reached:
        source = np.asarray(source, dtype=np.float64)
        if np.abs(points[-1] - source).max() <= 1e-9 * min(hx, hy):
            points[-1], vals[-1] = source, 0.0  # ended on the source's own node
        else:
            points = np.vstack([points, source])
            vals = np.append(vals, 0.0)
    return Descent(points=points, values=vals, reached=bool(reached))


def descend_steps(grid: Grid, phi: np.ndarray, start: np.ndarray, max_steps: int) -> np.ndarray | None:
    """Up to ``max_steps`` half-spacing steps down ``phi`` from ``start``
    (metres, (n, 2)): a look ahead along the path. Where ``phi`` is infinite
    at ``start``'s nearest node, the steps start from the nearest finite node
    within about one spacing; None if there is none. ``phi`` is a float64
    array of the grid's shape and ``start`` a point on the grid: nothing is
    checked."""
    lx, ly = (float(c) for c in grid.lo)
    hx, hy = (float(h) for h in grid.spacing)
    fx, fy = (start[0] - lx) / hx, (start[1] - ly) / hy
    i = min(max(int(fx + 0.5), 0), phi.shape[0] - 1)
    j = min(max(int(fy + 0.5), 0), phi.shape[1] - 1)
    if not phi[i, j] < np.inf:
        # The nodes within about one spacing: the window of the cell's corners and their neighbours.
        ci, cj = int(math.floor(fx)), int(math.floor(fy))
        win = slice(max(ci - 1, 0), max(ci + 3, 0)), slice(max(cj - 1, 0), max(cj + 3, 0))
        ii, jj = np.nonzero(np.isfinite(phi[win]))
        if ii.size == 0:
            return None
        ii, jj = ii + win[0].start, jj + win[1].start
        q = int(np.argmin(np.hypot(ii - fx, jj - fy)))
        fx, fy = float(ii[q]), float(jj[q])
    stop = np.zeros(phi.shape, dtype=np.bool_)
    xs, ys, _, _ = _descend(phi, stop, hx, hy, fx, fy, np.int64(max_steps))
    return np.column_stack([xs * hx + lx, ys * hy + ly])


def aim_ahead(grid: Grid, phi: np.ndarray, stop: np.ndarray, start: np.ndarray, steps: int, distance: float):
    """Where a walker at ``start`` steers: the first point of its
    steepest-descent path (``descend`` with ``seeds=stop``) at least
    ``distance`` metres along it, or the path's end if it is shorter. The
    path is traced ``steps`` steps, and to its end only where that falls
    short. Returns the point and the path's number of points, or None where
    ``start`` is on no finite value. Point for point what ``descend`` and a
    search along its lengths give, without their checks and arrays, for
    walkers that ask ten times a second: ``phi`` float64 and ``stop`` bool,
    both C-contiguous and of the grid's shape, ``start`` on the grid."""
    lx, ly = (float(c) for c in grid.lo)
    hx, hy = (float(h) for h in grid.spacing)
    fx, fy = (start[0] - lx) / hx, (start[1] - ly) / hy  # grid.fractional_index's arithmetic
    full = 4 * grid.size + 16
    ax, ay, points = _aim(phi, stop, lx, ly, hx, hy, fx, fy, min(steps, full), full, distance)
    return None if points == 0 else (np.array([ax, ay]), points)


def compile_kernels() -> None:
    """Load or compile ``aim_ahead``'s kernel on a grid of three nodes a
    side. A kernel is compiled per argument type, not per grid, so a process
    that runs this fills numba's cache for every walker after it."""
    grid = Grid((0.0, 0.0), (1.0, 1.0), (3, 3))
    aim_ahead(grid, np.zeros(grid.shape), np.zeros(grid.shape, np.bool_), np.array([0.5, 0.5]), 1, 1.0)


# --------------------------------------------------------------------------- kernels


_STOPPED = 0
_STUCK = 1
_START_INVALID = 2


@numba.njit(cache=True)
def _descend(phi, stop, hx, hy, px, py, max_steps):
    """Descent from fractional index ``(px, py)``; see ``descend``."""
    nx, ny = phi.shape
    xs = np.empty(256)
    ys = np.empty(256)
    vals = np.empty(256)
    px = min(max(px, 0.0), nx - 1.0)
    py = min(max(py, 0.0), ny - 1.0)
    if not phi[int(px + 0.5), int(py + 0.5)] < np.inf:
        return xs[:0], ys[:0], vals[:0], _START_INVALID
    v = bilinear(phi, px, py)
    step = 0.5 * min(hx, hy)
    xs[0] = px
    ys[0] = py
    vals[0] = v
    m = 1
    status = _STUCK
    for _ in range(max_steps):
        ix = int(px + 0.5)
        iy = int(py + 0.5)
        if stop[ix, iy]:
            status = _STOPPED
            if phi[ix, iy] >= v:
                break
            px = float(ix)
            py = float(iy)
            v = phi[ix, iy]
        else:
            gx, gy = upwind_gradient(phi, px, py, hx, hy)
            norm = math.hypot(gx, gy)
            moved = False
            if norm > 0.0:
                qx = px - step * gx / (norm * hx)
                qy = py - step * gy / (norm * hy)
                inside = 0.0 <= qx <= nx - 1.0 and 0.0 <= qy <= ny - 1.0
                if inside and phi[int(qx + 0.5), int(qy + 0.5)] < np.inf:
                    vq = bilinear(phi, qx, qy)
                    if vq < v:
                        px = qx
                        py = qy
                        v = vq
                        moved = True
            if not moved:
                # The lowest finite node around; a diagonal move needs an open
                # side so it cannot slip between two blocked nodes.
                bx = -1
                by = -1
                best = v
                for a in range(max(ix - 1, 0), min(ix + 2, nx)):
                    for b in range(max(iy - 1, 0), min(iy + 2, ny)):
                        if phi[a, b] < best and (a == ix or b == iy or phi[a, iy] < np.inf or phi[ix, b] < np.inf):
                            best = phi[a, b]
                            bx = a
                            by = b
                if bx < 0:
                    break
                px = float(bx)
                py = float(by)
                v = best
        if m == vals.size:
            xs = _grow(xs)
            ys = _grow(ys)
            vals = _grow(vals)
        xs[m] = px
        ys[m] = py
        vals[m] = v
        m += 1
        if status == _STOPPED:
            break
    return xs[:m], ys[:m], vals[:m], status


@numba.njit(cache=True)
def _grow(a):
    b = np.empty(2 * a.size)
    for k in range(a.size):
        b[k] = a[k]
    return b


@numba.njit(cache=True)
def _aim(phi, stop, lx, ly, hx, hy, px, py, steps, full, distance):
    """``aim_ahead``'s work: the aim point and the path's length in points (0: no path)."""
    xs, ys, _, status = _descend(phi, stop, hx, hy, px, py, np.int64(steps))
    if status == _START_INVALID:
        return 0.0, 0.0, 0
    along = _along(xs, ys, lx, ly, hx, hy)
    if along[-1] < distance and xs.size == steps + 1:  # cut short of the look-ahead
        xs, ys, _, _ = _descend(phi, stop, hx, hy, px, py, np.int64(full))
        along = _along(xs, ys, lx, ly, hx, hy)
    k = xs.size - 1
    for i in range(xs.size):  # the first at or past ``distance``, as a search on the sorted lengths
        if along[i] >= distance:
            k = i
            break
    return lx + xs[k] * hx, ly + ys[k] * hy, xs.size


@numba.njit(cache=True)
def _along(xs, ys, lx, ly, hx, hy):
    """The distance along the path of fractional indices ``xs, ys`` to each of its points, in metres."""
    along = np.empty(xs.size)
    along[0] = 0.0
    for i in range(1, xs.size):
        dx = (lx + xs[i] * hx) - (lx + xs[i - 1] * hx)
        dy = (ly + ys[i] * hy) - (ly + ys[i - 1] * hy)
        along[i] = along[i - 1] + math.hypot(dx, dy)
    return along
