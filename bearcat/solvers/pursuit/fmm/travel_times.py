"""Travel times over a speed map from the points agents stand on, computed
once and kept, with what derives from them: times to capture and the
directions geodesics leave in."""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

import numba
import numpy as np

from bearcat.solvers.errors import InputError, non_negative
from bearcat.solvers.grid import Grid
from bearcat.solvers.marching import fmm
from bearcat.solvers.pursuit.fmm.rays import first_steps

__all__ = ["Front", "TravelTimes"]

T = TypeVar("T")


class Front:
    """The arrival times ``times`` (read-only) of a front leaving ``point`` at
    speed factor 1, and what derives from them, each computed once.

    ``source_speed`` is the speed factor where the front starts: how fast its
    times change as the source moves. Built by ``TravelTimes.front``.
    """

    __slots__ = ("_capture", "_first_steps", "_first_steps_limit", "_travel_times", "point", "source_speed", "times")

    def __init__(self, travel_times: TravelTimes, point: np.ndarray, times: np.ndarray, source_speed: float):
        self._travel_times = travel_times
        self.point = point
        self.times = times
        self.source_speed = source_speed
        self._capture: dict[float, np.ndarray] = {}
        self._first_steps: np.ndarray | None = None
        self._first_steps_limit = -math.inf

    def capture_time(self, radius: float) -> np.ndarray:
        """``psi^c`` at speed factor 1 with capture ``radius`` (a finite number
        >= 0): the time for the source to come within ``radius`` of each node."""
        psic = self._capture.get(radius)
        if psic is None:
            psic = fmm.time_to_capture(self.times, self._travel_times.spacing, radius)
            if psic is not self.times:
                psic.flags.writeable = False
            self._capture[radius] = psic
        return psic

    def first_steps(self, limit: float) -> np.ndarray:
        """Unit directions ``e`` (nx, ny, 2) in which the geodesics from the
        source to the nodes leave it, valid where ``times`` is at most ``limit``."""
        if self._first_steps is None or self._first_steps_limit < limit:
            tt = self._travel_times
            (lx, ly), (hx, hy) = tt.lo, tt.spacing
            p = self.point
            self._first_steps = first_steps(
                self.times, tt.speed, hx, hy, p[0] - lx, p[1] - ly, self.source_speed, float(limit)
            )
            self._first_steps_limit = limit
        return self._first_steps


class TravelTimes:
    """Travel times from points over ``speed``, the speed factor per node of
    ``grid`` (0 where blocked); every agent's top speed is a multiple of it.

    It keeps a least-recently-used cache of fronts keyed by start point
    (travel times scale as one over the speed, so one front serves every
    agent speed) and the last result derived from them (``derived``), so
    strategies sharing one ``TravelTimes`` share the work for the same
    positions: a pursuer that did not move, the evader and the pursuers
    asking about one state, a target held for many steps. ``order`` is that
    of the fast marching scheme. Not thread-safe.
    """

    def __init__(self, grid: Grid, speed: np.ndarray, *, order: int = 1, cache_size: int = 64):
        if grid.ndim != 2:
            raise InputError(f"travel times need a 2-D grid, got {grid.ndim} dimensions")
        speed = np.array(speed, dtype=np.float64)
        if speed.shape != grid.shape:
            raise InputError(f"speed has shape {speed.shape} but the grid has shape {grid.shape}")
        if not (np.isfinite(speed) & (speed >= 0)).all():
            raise InputError("speed has a negative, NaN or infinite value")
        if not (speed > 0).any():
            raise InputError("the speed map has no passable node")
        if order not in (1, 2):
            raise InputError(f"order must be 1 or 2, got {order!r}")
        if cache_size < 4:
            raise InputError(f"cache_size must be at least 4, got {cache_size}")
        speed.flags.writeable = False
        self.grid = grid
        self.speed = speed
        self.free = speed > 0
        self.free.flags.writeable = False
        self.order = order
        # The grid's first node and spacing as floats, as the kernels take them.
        self.lo = (float(grid.lo[0]), float(grid.lo[1]))
        self.spacing = (float(grid.spacing[0]), float(grid.spacing[1]))
        self._cache_size = int(cache_size)
        self._fronts: OrderedDict[tuple[float, float], Front] = OrderedDict()
        self._derived: tuple[Hashable, Any] | None = None  # the key and what its build returned

    def travel_time(self, point) -> np.ndarray:
        """Arrival times of a front leaving ``point`` at speed factor 1 (divide
        by an agent's speed scale for its times); read-only and cached."""
        return self.front(self.check_point(point, "point")).times

    def capture_time(self, point, radius: float) -> np.ndarray:
        """``psi^c`` at speed factor 1 of a pursuer at ``point`` with capture ``radius``."""
        return self.front(self.check_point(point, "point")).capture_time(non_negative(radius, "capture radius"))

    def front(self, point: np.ndarray) -> Front:
        """The front leaving ``point``, a point ``check_point`` accepted; cached."""
        key = (float(point[0]), float(point[1]))
        front = self._fronts.get(key)
        if front is not None:
            self._fronts.move_to_end(key)
            return front
        hx, hy = self.spacing
        initial = fmm.point_source(self.grid, point, self.speed)
        times = fmm.march(self.speed, hx, hy, initial, order=self.order)
        times.flags.writeable = False
        front = Front(self, point, times, self.source_speed(point))
        self._fronts[key] = front
        if len(self._fronts) > self._cache_size:
            self._fronts.popitem(last=False)
        return front

    def derived(self, key: Hashable, build: Callable[[], T], *, keep: bool = True) -> T:
        """``build()``, or what it returned the last time for an equal ``key``:
        what strategies sharing these travel times derive from one state is
        built once. One result is kept, the last one built with ``keep``."""
        if self._derived is not None and self._derived[0] == key:
            return self._derived[1]
        value = build()
        if keep:
            self._derived = (key, value)
        return value

    def source_speed(self, point: np.ndarray) -> float:
        """Speed factor of the passable node nearest ``point`` among those
        ``fmm.point_source`` seeds: how fast times change as the agent moves."""
        (lx, ly), (hx, hy) = self.lo, self.spacing
        k = _seed_node(self.free, lx, ly, hx, hy, point[0], point[1])
        return float(self.speed.flat[k])

    def check_point(self, point, name: str) -> np.ndarray:
        """``point`` as an array if a front can start there, else an InputError naming ``name``."""
        p = np.array(point, dtype=np.float64)
        if p.shape != (2,) or not (math.isfinite(p[0]) and math.isfinite(p[1])):
            raise InputError(f"{name} must be a finite (x, y) point, got {point!r}")
        if not self.grid.contains(p):
            lo, hi = self.grid.lo, self.grid.hi
            raise InputError(
                f"{name} at ({p[0]:g}, {p[1]:g}) lies outside the grid [{lo[0]:g}, {hi[0]:g}] x [{lo[1]:g}, {hi[1]:g}]"
            )
        (lx, ly), (hx, hy) = self.lo, self.spacing
        if _seed_node(self.free, lx, ly, hx, hy, p[0], p[1]) < 0:
            raise InputError(f"{name} at ({p[0]:g}, {p[1]:g}) has no passable grid node within one spacing")
        return p

    def check_points(self, points, name: str) -> np.ndarray:
        """``points`` as an (N, 2) array if a front can start at each, else an
        InputError naming the point (``name`` is a plural: "pursuers")."""
        q = np.asarray(points, dtype=np.float64)
        if q.size == 0:
            return np.zeros((0, 2))
        if q.ndim == 1 and q.size == 2:
            q = q[None]
        if q.ndim != 2 or q.shape[1] != 2:
            raise InputError(f"{name} must be an (N, 2) array of points, got shape {np.shape(points)}")
        return np.array([self.check_point(p, f"{name[:-1]} {k + 1}") for k, p in enumerate(q)])

    def placeable(self, point: np.ndarray) -> bool:
        """Whether an agent may stand at ``point``: on the grid, its nearest node free."""
        return self.grid.contains(point) and bool(self.free[self.grid.nearest_index(point)])


@numba.njit(cache=True)
def _seed_node(free, lox, loy, hx, hy, px, py):
    """Flat index of the nearest free node among those ``fmm.point_source``
    seeds for a source at ``p`` (its cell's corners and any node within one
    spacing), or -1 if none is free: the source cannot start there."""
    nx, ny = free.shape
    fx = (px - lox) / hx
    fy = (py - loy) / hy
    ci = min(max(int(math.floor(fx)), 0), nx - 2)
    cj = min(max(int(math.floor(fy)), 0), ny - 2)
    reach = max(hx, hy) * (1 + 1e-12)
    best = np.inf
    arg = -1
    for i in range(max(ci - 1, 0), min(ci + 3, nx)):
        for j in range(max(cj - 1, 0), min(cj + 3, ny)):
            d = math.hypot((i - fx) * hx, (j - fy) * hy)
            corner = ci <= i <= ci + 1 and cj <= j <= cj + 1
            if free[i, j] and (corner or d <= reach) and d < best:
                best = d
                arg = i * ny + j
    return arg
