"""Headings over a speed map: along the geodesic toward a front's source or
away from it, and turned off obstacles.

A heading never points into a blocked node: one that would is turned, by the
smallest angle, until the next grid spacing along it is free (the agent
slides along the obstacle).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from bearcat.solvers.marching.descent import descend_steps
from bearcat.solvers.pursuit.fmm.rays import sees
from bearcat.solvers.pursuit.fmm.travel_times import Front, TravelTimes

__all__ = ["away", "slide", "toward"]

_TURN_STEP = math.radians(5.0)
_LOOK_STEPS = 4  # half-spacing descent steps a heading looks ahead


def slide(
    travel_times: TravelTimes, p: np.ndarray, d: np.ndarray, max_turn: float = math.pi
) -> tuple[np.ndarray, bool]:
    """``d`` turned by the least angle, up to ``max_turn``, that keeps the next
    spacing from ``p`` free, and whether there was one."""
    (lx, ly), (hx, hy) = travel_times.lo, travel_times.spacing
    dx, dy, ok = _slide(travel_times.free, lx, ly, hx, hy, p[0], p[1], d[0], d[1], max_turn)
    return np.array([dx, dy]), bool(ok)


def toward(travel_times: TravelTimes, front: Front, p: np.ndarray) -> np.ndarray:
    """Unit heading from ``p`` along the geodesic to ``front``'s source:
    straight at it where the segment is a geodesic, else down the source's
    travel time, aiming one spacing ahead on the descent; slid clear."""
    target = front.point
    if math.hypot(*(target - p)) <= 1e-9:
        return np.zeros(2)
    if _in_sight(travel_times, p, target, travel_times.speed[travel_times.grid.nearest_index(p)]):
        return _unit_clear(travel_times, p, target - p)
    path = descend_steps(travel_times.grid, front.times, p, _LOOK_STEPS)
    if path is None:
        return np.zeros(2)
    gaps = np.hypot(*(path - p).T)
    ahead = np.flatnonzero(gaps >= 0.999 * max(travel_times.spacing))
    return _unit_clear(travel_times, p, path[ahead[0] if ahead.size else -1] - p)


def away(travel_times: TravelTimes, front: Front, q: np.ndarray) -> np.ndarray:
    """Unit heading from ``front``'s source along the geodesic to ``q``:
    straight where the segment is a geodesic, else the reversed last
    spacing of the descent from ``q`` down the source's own travel time."""
    p = front.point
    if math.hypot(*(q - p)) <= 1e-9:
        return np.zeros(2)
    if _in_sight(travel_times, p, q, front.source_speed):
        return _unit_clear(travel_times, p, q - p)
    path = descend_steps(travel_times.grid, front.times, q, 8 * sum(front.times.shape))
    if path is None:
        return np.zeros(2)
    gaps = np.hypot(*(path - p).T)
    back = np.flatnonzero(gaps >= 0.999 * max(travel_times.spacing))
    return _unit_clear(travel_times, p, path[back[-1] if back.size else 0] - p)


def _in_sight(travel_times: TravelTimes, p: np.ndarray, q: np.ndarray, v0: float) -> bool:
    """Whether the straight segment ``p -> q`` is a geodesic (same speed all along)."""
    (lx, ly), (hx, hy) = travel_times.lo, travel_times.spacing
    return bool(sees(travel_times.speed, v0, hx, hy, p[0] - lx, p[1] - ly, q[0] - lx, q[1] - ly))


def _unit_clear(travel_times: TravelTimes, p: np.ndarray, d: np.ndarray) -> np.ndarray:
    n = math.hypot(d[0], d[1])
    if not n > 1e-12:
        return np.zeros(2)
    d, ok = slide(travel_times, p, d / n)
    return d if ok else np.zeros(2)


@numba.njit(cache=True)
def _is_clear(free, lox, loy, hx, hy, px, py, dx, dy):
    """Whether the points every eighth of a spacing along ``d``, up to one
    spacing, lie in the grid and have free nearest nodes (the agent's own
    node excepted: an agent may stand closer to a blocked node than to any free one)."""
    nx, ny = free.shape
    reach = max(hx, hy)
    oi = min(max(int(math.floor((px - lox) / hx + 0.5)), 0), nx - 1)
    oj = min(max(int(math.floor((py - loy) / hy + 0.5)), 0), ny - 1)
    for q in range(1, 9):
        s = 0.125 * q * reach
        fi = (px + s * dx - lox) / hx
        fj = (py + s * dy - loy) / hy
        if fi < -1e-9 or fi > nx - 1 + 1e-9 or fj < -1e-9 or fj > ny - 1 + 1e-9:
            return False
        i = min(int(math.floor(fi + 0.5)), nx - 1)
        j = min(int(math.floor(fj + 0.5)), ny - 1)
        if (i != oi or j != oj) and not free[i, j]:
            return False
    return True


@numba.njit(cache=True)
def _slide(free, lox, loy, hx, hy, px, py, dx, dy, max_turn):
    """``d`` turned by the least multiple of 5 degrees, counter-clockwise first,
    up to ``max_turn``, that ``_is_clear``; (0, 0, False) if none is."""
    steps = int(max_turn / _TURN_STEP + 1e-9)
    for q in range(steps + 1):
        for sign in (1.0, -1.0):
            if q == 0 and sign < 0:
                continue
            a = sign * q * _TURN_STEP
            c = math.cos(a)
            s = math.sin(a)
            rx = c * dx - s * dy
            ry = s * dx + c * dy
            if _is_clear(free, lox, loy, hx, hy, px, py, rx, ry):
                return rx, ry, True
    return 0.0, 0.0, False
