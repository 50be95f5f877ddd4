"""Safe-reachable-area pursuit on a grid: non-convex domains, unequal speeds (thesis 5.2.2).

The evader's safe-reachable set ``S_e`` holds the nodes it reaches strictly
before any pursuer could capture it there, along a path of such nodes: the
modified fast marching method of thesis 4.1.3 and 4.1.5, run with
``solvers.fmm`` (one plain front per pursuer, its capture min-filter, and one
capped front from the evader). Pursuers that bound part of ``S_e`` (an
*active boundary*) move to shrink its area ``A``; the others close in along
the geodesic (pure pursuit that goes around obstacles).

Two ways to get ``dA/dx_p``:

``"finite"``, the thesis's: move each pursuer one cell along x and along y
and recount ``S_e``. ``2N + 1`` modified-FMM solves a step, and a count of
nodes is a staircase in the pursuer's position, so the difference is noisy.

``"boundary"``: the first variation of the area. Write ``f = psi_i^c - phi``
(positive inside ``S_e``) on the part of the boundary pursuer ``i`` owns.
Moving the pursuer changes ``psi_i^c`` by ``delta psi``, which moves that
boundary outward by ``delta psi / |grad f|``, so

    dA/dx_p^i = integral over pursuer i's active boundary of
                (d psi_i^c / d x_p^i) / |grad (psi_i^c - phi)| ds.

For an isotropic speed the travel time is symmetric in its end points, so its
gradient with respect to the *source* is the gradient of the travel time from
the target evaluated at the source: ``-e(y) / v(x_p)``, where ``e(y)`` is the
unit direction in which the geodesic from the pursuer to ``y`` leaves the
pursuer (moving the pursuer along its first step shortens every geodesic
that starts that way, at the pursuer's speed). With a capture radius,
``psi_i^c(y) = psi_i(x*)`` for the node ``x*`` of the capture disk the
pursuer reaches first, and the derivative is ``-e(x*) / v``. In a convex
domain with equal speeds this integral is exactly Lemma 3: on the bisector
``|grad f| = |xi| / |y - x_p|`` and the integrand is ``-(y - x_p) / |xi|``,
whose components along ``eta_h`` and ``eta_v`` integrate to ``-L/2`` and
``(l^2 - (L - l)^2) / (2 |xi|)``.

``e`` is constant along every ray of the pursuer's front, so it is known
exactly where the pursuer sees the point in a straight line at its own speed
(the direction to the point) and is carried, in arrival order, from the
upwind neighbours elsewhere (behind a corner every ray leaves toward that
corner, a constant the transport keeps exactly; plain upwind transport from
the source smears the direction by up to 18 degrees on a 100 x 100 grid).
``|grad f|`` takes the sizes of ``grad psi^c`` and ``grad phi`` from the
eikonal equation (one over the local speed) and their directions from the
geometry: the straight line from an agent that sees the point, the
finite-difference gradient of its front otherwise. Differencing the two
first-order fields instead gets ``|grad f|`` wrong several times over where
it is small (``|xi| / r`` on a bisector, far from close agents).

The integral is a sum over the grid edges from ``S_e`` to a free node
outside it, each standing for the length of boundary that crosses it. Two
discrete cases are set apart. Where ``psi^c`` jumps across the edge (the
capture disk reaches through a wall on one side and not on the other, which
the maze's half-metre walls and half-metre capture radius make common), the
boundary stays on the wall face whatever the pursuer does, and the edge
counts for nothing. Where both fronts arrive together through one door,
``grad f`` vanishes and the area truly jumps; ``|grad f|`` is floored at one
percent of the slowness so those edges dominate without overflowing, which
sends the pursuer to the door. The method needs only the ``N`` pursuer
fronts and the evader's capped front of the safe set itself.

Every front is cached in the ``FmmArena`` by the position it starts from, so
a pursuer that did not move, the evader strategy and the pursuers asking
about the same positions, or a fixed target reuse their travel times. A
pursuer with no active boundary takes the geodesic toward the evader read
from its own front, already computed for the safe set.

Headings never point into a blocked node: a heading that would is turned,
by the smallest angle, until the next grid spacing along it is free (the
agent slides along the obstacle).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numba
import numpy as np

from bearcat.solvers import fmm
from bearcat.solvers.errors import InputError, non_negative, positive
from bearcat.solvers.grid import Grid

__all__ = [
    "AreaGradient",
    "FarthestPointEvader",
    "FmmAreaPursuit",
    "FmmArena",
    "GeodesicPursuit",
    "SafeSet",
    "safe_set",
]

_GRADIENTS = ("boundary", "finite")
_TURN_STEP = math.radians(5.0)
# Beyond this turn a wall-deflected area heading lowers A at less than half
# the steepest rate. A pursuer pressed against a wall between it and the
# evader then chatters about the point where the wall's tangent is level in
# A and never captures (triangle-10, one pursuer: 2 of 150 trials with 85
# degrees, none with 60); the geodesic takes it round the obstacle instead.
_DESCENT_TURN = math.radians(60.0)
_MIN_ACTIVE_CELLS = 2.0  # an active boundary shorter than this many spacings is junction noise
_LOOK_STEPS = 4  # half-spacing descent steps a heading looks ahead
_FLAT = 0.01  # floor of |grad f| as a fraction of the smaller slowness (module notes)
_JUMP = 2.5  # psi^c steeper than this many slownesses across an edge is a jump (module notes)


@dataclass(frozen=True, eq=False)
class SafeSet:
    """The evader's safe-reachable set ``S_e`` on the arena's grid.

    ``mask`` marks the nodes of ``S_e``; ``area`` is ``N_s h^2``.
    ``evader_time`` is the evader's arrival time ``phi`` along safe paths
    (infinite outside ``S_e``); ``pursuer_times[i]`` is pursuer ``i``'s time
    to capture ``psi_i^c`` (N, nx, ny); ``owner`` is the pursuer with the
    least ``psi^c`` at each node, the one that bounds ``S_e`` there (-1 where
    no pursuer can come). Arrays are read-only: caches share them.
    """

    mask: np.ndarray
    area: float
    evader_time: np.ndarray
    pursuer_times: np.ndarray
    owner: np.ndarray

    @property
    def capture_time(self) -> np.ndarray:
        """``psi^c = min_i psi_i^c``, the ceiling the evader's front ran under."""
        if len(self.pursuer_times) == 0:
            return np.full(self.mask.shape, np.inf)
        return self.pursuer_times.min(axis=0)


@dataclass(frozen=True, eq=False)
class AreaGradient:
    """``gradient[i]`` is ``dA/dx_p^i`` (square metres per metre), zero for a
    pursuer without an active boundary; ``active[i]`` tells whether pursuer
    ``i`` bounds a part of ``S_e`` at least two spacings long, and
    ``boundary_length[i]`` how long that part is (metres)."""

    safe: SafeSet
    gradient: np.ndarray
    active: np.ndarray
    boundary_length: np.ndarray


class _Front:
    """A front leaving ``point`` at speed factor 1, and what is derived from it."""

    __slots__ = ("capture", "point", "psi", "rays", "rays_limit", "source_speed")

    def __init__(self, point: np.ndarray, psi: np.ndarray, source_speed: float):
        self.point = point
        self.psi = psi
        self.source_speed = source_speed
        self.capture: dict[float, np.ndarray] = {}
        self.rays: np.ndarray | None = None
        self.rays_limit = -math.inf


class FmmArena:
    """The domain of the game: ``grid`` and the speed factor per node (0 where
    blocked); every agent's top speed is a multiple of it.

    It keeps a least-recently-used cache of fronts keyed by start point
    (travel times scale as one over the speed, so one front serves every
    agent speed) and the last safe set, so strategies sharing an arena share
    the work for the same positions: a pursuer that did not move, the evader
    and the pursuers asking about one state, a target held for many steps.
    ``order`` is that of the fast marching scheme. Not thread-safe.
    """

    def __init__(self, grid: Grid, speed: np.ndarray, *, order: int = 1, cache_size: int = 64):
        if grid.ndim != 2:
            raise InputError(f"the pursuit arena is a 2-D grid, got {grid.ndim} dimensions")
        speed = np.array(speed, dtype=np.float64)
        if speed.shape != grid.shape:
            raise InputError(f"speed has shape {speed.shape} but the grid has shape {grid.shape}")
        if not (np.isfinite(speed) & (speed >= 0)).all():
            raise InputError("speed has a negative, NaN or infinite value")
        if not (speed > 0).any():
            raise InputError("the arena has no passable node")
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
        self._lo = (float(grid.lo[0]), float(grid.lo[1]))
        self._h = (float(grid.spacing[0]), float(grid.spacing[1]))
        self._no_stop = np.zeros(grid.shape, dtype=np.bool_)
        self._cache_size = int(cache_size)
        self._fronts: OrderedDict[tuple[float, float], _Front] = OrderedDict()
        self._last_safe: tuple[tuple, SafeSet] | None = None

    def travel_time(self, point) -> np.ndarray:
        """Arrival times of a front leaving ``point`` at speed factor 1 (divide
        by an agent's speed scale for its times); read-only and cached."""
        return self._front(self._point(point, "point")).psi

    def capture_time(self, point, radius: float) -> np.ndarray:
        """``psi^c`` at speed factor 1 of a pursuer at ``point`` with capture ``radius``."""
        return self._capture(self._front(self._point(point, "point")), non_negative(radius, "capture radius"))

    # ------------------------------------------------------------------ fronts

    def _front(self, p: np.ndarray) -> _Front:
        key = (float(p[0]), float(p[1]))
        front = self._fronts.get(key)
        if front is not None:
            self._fronts.move_to_end(key)
            return front
        hx, hy = self._h
        initial = fmm.point_source(self.grid, p, self.speed)
        psi = fmm.march(self.speed, hx, hy, initial, order=self.order)
        psi.flags.writeable = False
        front = _Front(p, psi, self._seed_speed(p))
        self._fronts[key] = front
        if len(self._fronts) > self._cache_size:
            self._fronts.popitem(last=False)
        return front

    def _capture(self, front: _Front, radius: float) -> np.ndarray:
        psic = front.capture.get(radius)
        if psic is None:
            psic = fmm.time_to_capture(front.psi, self._h, radius)
            if psic is not front.psi:
                psic.flags.writeable = False
            front.capture[radius] = psic
        return psic

    def _rays(self, front: _Front, limit: float) -> np.ndarray:
        """First-step directions ``e`` of the geodesics from the front's source,
        valid where its travel time is at most ``limit``."""
        if front.rays is None or front.rays_limit < limit:
            (lx, ly), (hx, hy) = self._lo, self._h
            p = front.point
            front.rays = _ray_directions(
                front.psi, self.speed, hx, hy, p[0] - lx, p[1] - ly, front.source_speed, float(limit)
            )
            front.rays_limit = limit
        return front.rays

    def _seed_speed(self, p: np.ndarray) -> float:
        """Speed factor of the passable node nearest ``p`` among those
        ``point_source`` seeds: how fast times change as the agent moves."""
        (lx, ly), (hx, hy) = self._lo, self._h
        k = _seed_node(self.free, lx, ly, hx, hy, p[0], p[1])
        return float(self.speed.flat[k])

    # ------------------------------------------------------------------ points

    def _window(self, p) -> tuple[slice, slice]:
        """Index window of the nodes within about one spacing of ``p``."""
        i = int(math.floor((p[0] - self._lo[0]) / self._h[0]))
        j = int(math.floor((p[1] - self._lo[1]) / self._h[1]))
        return slice(max(i - 1, 0), max(i + 3, 0)), slice(max(j - 1, 0), max(j + 3, 0))

    def _point(self, point, name: str) -> np.ndarray:
        p = np.array(point, dtype=np.float64)
        if p.shape != (2,) or not (math.isfinite(p[0]) and math.isfinite(p[1])):
            raise InputError(f"{name} must be a finite (x, y) point, got {point!r}")
        if not self.grid.contains(p):
            lo, hi = self.grid.lo, self.grid.hi
            raise InputError(
                f"{name} at ({p[0]:g}, {p[1]:g}) lies outside the grid [{lo[0]:g}, {hi[0]:g}] x [{lo[1]:g}, {hi[1]:g}]"
            )
        (lx, ly), (hx, hy) = self._lo, self._h
        if _seed_node(self.free, lx, ly, hx, hy, p[0], p[1]) < 0:
            raise InputError(f"{name} at ({p[0]:g}, {p[1]:g}) has no passable grid node within one spacing")
        return p

    def _points(self, points, name: str) -> np.ndarray:
        q = np.asarray(points, dtype=np.float64)
        if q.size == 0:
            return np.zeros((0, 2))
        if q.ndim == 1 and q.size == 2:
            q = q[None]
        if q.ndim != 2 or q.shape[1] != 2:
            raise InputError(f"{name} must be an (N, 2) array of points, got shape {np.shape(points)}")
        return np.array([self._point(p, f"{name[:-1]} {k + 1}") for k, p in enumerate(q)])

    def _placeable(self, p: np.ndarray) -> bool:
        return self.grid.contains(p) and bool(self.free[self.grid.nearest_index(p)])

    # ------------------------------------------------------------------ headings

    def _sees(self, p: np.ndarray, q: np.ndarray, v0: float) -> bool:
        """Whether the straight segment ``p -> q`` is a geodesic (same speed all along)."""
        (lx, ly), (hx, hy) = self._lo, self._h
        return bool(_sees(self.speed, v0, hx, hy, p[0] - lx, p[1] - ly, q[0] - lx, q[1] - ly))

    def _clear(self, p: np.ndarray, d: np.ndarray, max_turn: float = math.pi) -> tuple[np.ndarray, bool]:
        """``d`` turned by the least angle, up to ``max_turn``, that keeps the next spacing free."""
        (lx, ly), (hx, hy) = self._lo, self._h
        dx, dy, ok = _slide(self.free, lx, ly, hx, hy, p[0], p[1], d[0], d[1], max_turn)
        return np.array([dx, dy]), bool(ok)

    def _unit_clear(self, p: np.ndarray, d: np.ndarray) -> np.ndarray:
        n = math.hypot(d[0], d[1])
        if not n > 1e-12:
            return np.zeros(2)
        d, ok = self._clear(p, d / n)
        return d if ok else np.zeros(2)

    def _path(self, psi: np.ndarray, start: np.ndarray, steps: int) -> np.ndarray | None:
        """Up to ``steps`` half-spacing steps down ``psi`` from ``start`` (metres,
        (n, 2)), starting from the nearest reached node if ``start``'s is not."""
        (lx, ly), (hx, hy) = self._lo, self._h
        fx, fy = (start[0] - lx) / hx, (start[1] - ly) / hy
        i = min(max(int(fx + 0.5), 0), psi.shape[0] - 1)
        j = min(max(int(fy + 0.5), 0), psi.shape[1] - 1)
        if not psi[i, j] < np.inf:
            win = self._window(start)
            ii, jj = np.nonzero(np.isfinite(psi[win]))
            if ii.size == 0:
                return None
            ii, jj = ii + win[0].start, jj + win[1].start
            q = int(np.argmin(np.hypot(ii - fx, jj - fy)))
            fx, fy = float(ii[q]), float(jj[q])
        xs, ys, _, _ = fmm._descend(psi, self._no_stop, hx, hy, fx, fy, np.int64(steps))
        return np.column_stack([xs * hx + lx, ys * hy + ly])

    def _toward(self, front: _Front, p: np.ndarray) -> np.ndarray:
        """Unit heading from ``p`` along the geodesic to ``front``'s source:
        straight at it where the segment is a geodesic, else down the source's
        travel time, aiming one spacing ahead on the descent; slid clear."""
        target = front.point
        if math.hypot(*(target - p)) <= 1e-9:
            return np.zeros(2)
        if self._sees(p, target, self.speed[self.grid.nearest_index(p)]):
            return self._unit_clear(p, target - p)
        path = self._path(front.psi, p, _LOOK_STEPS)
        if path is None:
            return np.zeros(2)
        gaps = np.hypot(*(path - p).T)
        ahead = np.flatnonzero(gaps >= 0.999 * max(self._h))
        return self._unit_clear(p, path[ahead[0] if ahead.size else -1] - p)

    def _away(self, front: _Front, q: np.ndarray) -> np.ndarray:
        """Unit heading from ``front``'s source along the geodesic to ``q``:
        straight where the segment is a geodesic, else the reversed last
        spacing of the descent from ``q`` down the source's own travel time."""
        p = front.point
        if math.hypot(*(q - p)) <= 1e-9:
            return np.zeros(2)
        if self._sees(p, q, front.source_speed):
            return self._unit_clear(p, q - p)
        path = self._path(front.psi, q, 8 * sum(front.psi.shape))
        if path is None:
            return np.zeros(2)
        gaps = np.hypot(*(path - p).T)
        back = np.flatnonzero(gaps >= 0.999 * max(self._h))
        return self._unit_clear(p, path[back[-1] if back.size else 0] - p)


# ---------------------------------------------------------------------- safe set


def safe_set(
    arena: FmmArena,
    evader,
    pursuers,
    *,
    evader_speed: float = 1.0,
    pursuer_speeds=1.0,
    capture_radius: float = 0.5,
) -> SafeSet:
    """``S_e``: the nodes the evader reaches strictly before every pursuer's
    time to capture, along paths of such nodes (thesis 4.1.3, 4.1.5, 5.2.2).

    Speeds scale the arena's speed factor; ``pursuer_speeds`` is one number
    or one per pursuer. An evader already within the capture radius of a
    pursuer has an empty set.
    """
    e = arena._point(evader, "evader")
    ps = arena._points(pursuers, "pursuers")
    speeds = _speeds(pursuer_speeds, len(ps))
    return _safe_set(
        arena, e, ps, positive(evader_speed, "evader speed"), speeds, non_negative(capture_radius, "capture radius")
    )


def _safe_set(arena: FmmArena, e, ps, ve: float, speeds, radius: float, remember: bool = True) -> SafeSet:
    key = (tuple(e), tuple(map(tuple, ps)), ve, tuple(speeds), radius)
    if arena._last_safe is not None and arena._last_safe[0] == key:
        return arena._last_safe[1]
    g = arena.grid
    hx, hy = arena._h
    n = len(ps)
    psic = np.empty((n,) + g.shape)
    for k, (p, s) in enumerate(zip(ps, speeds)):
        np.divide(arena._capture(arena._front(p), radius), s, out=psic[k])
    owner, ceiling = _owner(psic)
    if n and np.hypot(*(ps - e).T).min() <= radius:
        phi = np.full(g.shape, np.inf)  # captured already
    else:
        # The evader's front at speed factor 1 under the ceiling in the same units.
        initial = fmm.point_source(g, e, arena.speed)
        phi = fmm.march(arena.speed, hx, hy, initial, ceiling * ve, arena.order)
        phi /= ve
    mask = np.isfinite(phi)
    for a in (mask, phi, psic, owner):
        a.flags.writeable = False
    area = float(mask.sum()) * g.cell_area
    safe = SafeSet(mask=mask, area=area, evader_time=phi, pursuer_times=psic, owner=owner)
    if remember:
        arena._last_safe = (key, safe)
    return safe


# ---------------------------------------------------------------------- strategies


class _Game:
    """The arena and the game's speeds and capture radius, checked once,
    shared by the strategies and the evader that need the safe set."""

    def __init__(self, arena: FmmArena, evader_speed, pursuer_speeds, capture_radius) -> None:
        self.arena = arena
        self.evader_speed = positive(evader_speed, "evader speed")
        self.pursuer_speeds = _speeds(pursuer_speeds, None)
        self.capture_radius = non_negative(capture_radius, "capture radius")

    def _safe(self, e: np.ndarray, ps: np.ndarray) -> SafeSet:
        speeds = _speeds(self.pursuer_speeds, len(ps))
        return _safe_set(self.arena, e, ps, self.evader_speed, speeds, self.capture_radius)


class FmmAreaPursuit(_Game):
    """Pursuers that shrink the area of ``S_e`` (thesis 5.2.2); the module
    notes describe the two ``gradient`` methods. ``"boundary"`` is the
    default: it follows the area where one-cell differences of a node count
    cannot (a boundary parallel to the grid does not move a node for a
    half-cell shift of the bisector), turns headings about five times less
    from step to step, and costs half as much. A pursuer without an active
    boundary, or whose area heading has no free direction within 60 degrees
    (none that lowers the area at half the steepest rate or more), takes the
    geodesic toward the evader, read from its own front, which is already
    computed."""

    def __init__(
        self,
        arena: FmmArena,
        *,
        evader_speed: float = 1.0,
        pursuer_speeds=1.0,
        capture_radius: float = 0.5,
        gradient: str = "boundary",
    ):
        if gradient not in _GRADIENTS:
            raise InputError(f"gradient must be one of {', '.join(_GRADIENTS)}, got {gradient!r}")
        super().__init__(arena, evader_speed, pursuer_speeds, capture_radius)
        self.gradient = gradient

    def area_gradient(self, evader, pursuers) -> AreaGradient:
        """``dA/dx_p`` of every pursuer, by this strategy's method."""
        arena = self.arena
        return self._area_gradient(arena._point(evader, "evader"), arena._points(pursuers, "pursuers"))

    def headings(self, evader, pursuers) -> np.ndarray:
        """(N, 2) unit headings: ``-dA/dx_p`` for the pursuers with an active
        boundary, the geodesic toward the evader for the others."""
        arena = self.arena
        e = arena._point(evader, "evader")
        ps = arena._points(pursuers, "pursuers")
        ag = self._area_gradient(e, ps)
        out = np.zeros((len(ps), 2))
        for k, p in enumerate(ps):
            g = ag.gradient[k]
            norm = math.hypot(g[0], g[1])
            if ag.active[k] and norm > 0:
                d, ok = arena._clear(p, -g / norm, _DESCENT_TURN)
                if ok:
                    out[k] = d
                    continue
            out[k] = arena._away(arena._front(p), e)
        return out

    def _area_gradient(self, e: np.ndarray, ps: np.ndarray) -> AreaGradient:
        arena = self.arena
        n = len(ps)
        speeds = _speeds(self.pursuer_speeds, n)
        safe = self._safe(e, ps)
        a, b, owner = _boundary_edges(arena, safe)
        length = np.zeros(n)
        bounds: dict[int, _Boundary] = {}
        for k in np.unique(owner):
            sel = owner == k
            bounds[k] = _Boundary(
                arena, e, k, ps[k], speeds[k], self.evader_speed, self.capture_radius, safe, a[sel], b[sel]
            )
            length[k] = bounds[k].length.sum()
        active = length >= _MIN_ACTIVE_CELLS * max(arena._h)
        grad = np.zeros((n, 2))
        for k in np.flatnonzero(active):
            if self.gradient == "boundary":
                grad[k] = bounds[k].gradient()
            else:
                grad[k] = _finite_gradient(arena, e, ps, speeds, k, self.evader_speed, self.capture_radius)
        for x in (grad, active, length):
            x.flags.writeable = False
        return AreaGradient(safe=safe, gradient=grad, active=active, boundary_length=length)


class GeodesicPursuit:
    """Pure pursuit along the geodesic: one front from the evader, and each
    pursuer heads down its travel time (straight at the evader where the
    segment is the geodesic), so around obstacles rather than into them."""

    def __init__(self, arena: FmmArena):
        self.arena = arena

    def headings(self, evader, pursuers) -> np.ndarray:
        arena = self.arena
        e = arena._point(evader, "evader")
        ps = arena._points(pursuers, "pursuers")
        front = arena._front(e)
        return np.array([arena._toward(front, p) for p in ps]).reshape(-1, 2)


class FarthestPointEvader(_Game):
    """The evader of thesis 5.3.2: it heads for ``y*``, the node of ``S_e`` it
    reaches last along safe paths (``argmax phi``), keeps that target until
    within half the capture radius of it (at least one spacing, so that point
    capture still re-targets), then picks the next. The heading is the first
    step of the geodesic to ``y*``, down the travel time from ``y*``: one
    front per target, reused while the target holds. With an empty ``S_e``
    it keeps heading for its old target, or stands still without one."""

    def __init__(
        self,
        arena: FmmArena,
        *,
        evader_speed: float = 1.0,
        pursuer_speeds=1.0,
        capture_radius: float = 0.5,
    ):
        super().__init__(arena, evader_speed, pursuer_speeds, capture_radius)
        self.target: np.ndarray | None = None
        self.retargets = 0

    @property
    def arrival_radius(self) -> float:
        return max(self.capture_radius / 2, max(self.arena._h))

    def heading(self, evader, pursuers) -> np.ndarray:
        arena = self.arena
        e = arena._point(evader, "evader")
        if self.target is None or math.hypot(*(self.target - e)) <= self.arrival_radius:
            ps = arena._points(pursuers, "pursuers")
            safe = self._safe(e, ps)
            if safe.mask.any():
                far = int(np.argmax(np.where(safe.mask, safe.evader_time, -np.inf)))
                self.target = arena.grid.point(np.unravel_index(far, safe.mask.shape))
                self.retargets += 1
        if self.target is None:
            return np.zeros(2)
        return arena._toward(arena._front(self.target), e)


# ---------------------------------------------------------------------- gradients


def _boundary_edges(arena: FmmArena, safe: SafeSet):
    """Grid edges from a node ``a`` of ``S_e`` to a free node ``b`` outside it,
    and the pursuer that cut ``b`` off (flat indices)."""
    if len(safe.pursuer_times) == 0 or not safe.mask.any():
        z = np.zeros(0, dtype=np.int64)
        return z, z, z
    return _edges(safe.mask, arena.free, safe.owner)


class _Boundary:
    """Pursuer ``k``'s part of the boundary: per edge the boundary length it
    stands for, that length over ``|grad f|``, and ``e(x*)`` (module notes)."""

    def __init__(self, arena: FmmArena, e, k: int, p, speed, ve: float, radius: float, safe: SafeSet, a, b):
        # a, b: the flat nodes of pursuer k's edges, inside and outside S_e.
        self.arena = arena
        self.front = arena._front(p)
        self.speed = float(speed)
        (lx, ly), (hx, hy) = arena._lo, arena._h
        widths = fmm.disk_widths(radius, hx, hy)
        self.xa = _capture_points(self.front.psi, a, widths)
        self.xb = _capture_points(self.front.psi, b, widths)
        self._args = (
            a,
            b,
            self.xa,
            self.xb,
            self.front.psi,
            safe.pursuer_times[k],
            safe.evader_time,
            arena.speed,
            p[0] - lx,
            p[1] - ly,
            self.front.source_speed,
            self.speed,
            e[0] - lx,
            e[1] - ly,
            arena._seed_speed(e),
            float(ve),
            hx,
            hy,
        )
        self.length, self.weight, self.e, self.missing = _edge_terms(*self._args, _NO_RAYS)

    def gradient(self) -> np.ndarray:
        """``dA/dx_p = -(1 / v) sum weight * e``, ``v`` the pursuer's speed where it stands."""
        if self.missing.any():
            # Some capture points are out of the pursuer's sight: carry the directions there.
            flat = self.front.psi.ravel()
            limit = float(max(flat[self.xa].max(), flat[self.xb].max()))
            rays = self.arena._rays(self.front, limit)
            self.length, self.weight, self.e, self.missing = _edge_terms(*self._args, rays)
        v = self.speed * self.front.source_speed
        return -(self.weight[:, None] * self.e).sum(axis=0) / v


_NO_RAYS = np.zeros((0, 0, 2))


def _finite_gradient(arena: FmmArena, e, ps, speeds, k: int, ve: float, radius: float) -> np.ndarray:
    """One-cell forward differences of ``N_s h^2`` along x and y (thesis
    5.2.2); backward where the forward node is blocked, zero where both are."""
    safe = _safe_set(arena, e, ps, ve, speeds, radius)
    grad = np.zeros(2)
    for axis in (0, 1):
        h = arena._h[axis]
        for sign in (1.0, -1.0):
            q = ps.copy()
            q[k, axis] += sign * h
            if not arena._placeable(q[k]):
                continue
            moved = _safe_set(arena, e, q, ve, speeds, radius, remember=False)
            grad[axis] = sign * (moved.area - safe.area) / h
            break
    return grad


# ---------------------------------------------------------------------- helpers


def _speeds(value, n: int | None) -> np.ndarray:
    s = np.asarray(value, dtype=np.float64)
    if s.ndim > 1 or not (np.isfinite(s) & (s > 0)).all():
        raise InputError(f"pursuer speeds must be positive finite numbers, got {value!r}")
    if n is None:
        return s
    if s.ndim == 1 and s.size != n:
        raise InputError(f"got {s.size} pursuer speeds for {n} pursuers")
    return np.broadcast_to(s, (n,)).astype(np.float64)


# ---------------------------------------------------------------------- kernels


@numba.njit(cache=True)
def _owner(psic):
    """The pursuer with the least time to capture at each node (-1 where none
    comes), and that time: ``psi^c = min_i psi_i^c``, the evader's ceiling."""
    n, nx, ny = psic.shape
    owner = np.full((nx, ny), -1, dtype=np.int64)
    ceiling = np.full((nx, ny), np.inf)
    for k in range(n):
        for i in range(nx):
            for j in range(ny):
                if psic[k, i, j] < ceiling[i, j]:
                    ceiling[i, j] = psic[k, i, j]
                    owner[i, j] = k
    return owner, ceiling


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


@numba.njit(cache=True, error_model="numpy")
def _ray_directions(psi, speed, hx, hy, sx, sy, v0, limit):
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
    seen = np.zeros((nx, ny))  # 1 seen, 0 unseen or blocked, -1 not visited yet
    for i in range(nx):
        for j in range(ny):
            if speed[i, j] > 0 and psi[i, j] <= limit:
                seen[i, j] = -1.0
    order = _sorted_nodes(psi, limit)
    step = min(hx, hy)
    near = 1.01 * math.hypot(hx, hy)
    for k in order:
        i = k // ny
        j = k - i * ny
        t = psi[i, j]
        dx = i * hx - sx
        dy = j * hy - sy
        r = math.hypot(dx, dy)
        visible = False
        if speed[i, j] == v0:
            if r <= near:
                visible = True
            else:
                # Bilinear weight of the seen corners around the point one step back.
                fx = (i * hx - step * dx / r) / hx
                fy = (j * hy - step * dy / r) / hy
                ci = min(max(int(math.floor(fx)), 0), nx - 2)
                cj = min(max(int(math.floor(fy)), 0), ny - 2)
                ax = fx - ci
                ay = fy - cj
                num = 0.0
                den = 0.0
                for a in range(2):
                    for b in range(2):
                        w = (ax if a else 1.0 - ax) * (ay if b else 1.0 - ay)
                        s = seen[ci + a, cj + b]
                        if s >= 0.0:  # visited, or blocked
                            num += w * s
                            den += w
                visible = den > 0.0 and num > 0.5 * den
        if visible:
            seen[i, j] = 1.0
            if r > 0.0:
                out[i, j, 0] = dx / r
                out[i, j, 1] = dy / r
            continue
        seen[i, j] = 0.0
        ex = 0.0
        ey = 0.0
        ws = 0.0
        lo = psi[i - 1, j] if i > 0 else np.inf
        hi = psi[i + 1, j] if i < nx - 1 else np.inf
        up = i - 1 if lo <= hi else i + 1
        b = min(lo, hi)
        if b < t:
            w = (t - b) / (hx * hx)
            ex += w * out[up, j, 0]
            ey += w * out[up, j, 1]
            ws += w
        lo = psi[i, j - 1] if j > 0 else np.inf
        hi = psi[i, j + 1] if j < ny - 1 else np.inf
        up = j - 1 if lo <= hi else j + 1
        b = min(lo, hi)
        if b < t:
            w = (t - b) / (hy * hy)
            ex += w * out[i, up, 0]
            ey += w * out[i, up, 1]
            ws += w
        norm = math.hypot(ex, ey)
        if norm > 0.0:
            out[i, j, 0] = ex / norm
            out[i, j, 1] = ey / norm
        elif r > 0.0:
            out[i, j, 0] = dx / r
            out[i, j, 1] = dy / r
    return out


@numba.njit(cache=True)
def _slope(field, i, j, di, dj, h):
    """Central difference of ``field`` at (i, j) along (di, dj), one-sided next
    to an infinite or missing neighbour, 0 with neither."""
    nx, ny = field.shape
    lo = field[i - di, j - dj] if i - di >= 0 and j - dj >= 0 else np.inf
    hi = field[i + di, j + dj] if i + di < nx and j + dj < ny else np.inf
    c = field[i, j]
    if lo < np.inf and hi < np.inf:
        return (hi - lo) / (2.0 * h)
    if hi < np.inf:
        return (hi - c) / h
    if lo < np.inf:
        return (c - lo) / h
    return 0.0


@numba.njit(cache=True)
def _edges(mask, free, owner):
    """Edges from a node of ``mask`` to a free node outside it, with its owner."""
    nx, ny = mask.shape
    cap = 0
    for i in range(nx):
        for j in range(ny):
            if mask[i, j]:
                cap += 4
    a_out = np.empty(cap, dtype=np.int64)
    b_out = np.empty(cap, dtype=np.int64)
    k_out = np.empty(cap, dtype=np.int64)
    m = 0
    for i in range(nx):
        for j in range(ny):
            if not mask[i, j]:
                continue
            for d in range(4):
                bi = i + (d == 1) - (d == 0)
                bj = j + (d == 3) - (d == 2)
                if bi < 0 or bi >= nx or bj < 0 or bj >= ny:
                    continue
                if mask[bi, bj] or not free[bi, bj] or owner[bi, bj] < 0:
                    continue
                a_out[m] = i * ny + j
                b_out[m] = bi * ny + bj
                k_out[m] = owner[bi, bj]
                m += 1
    return a_out[:m], b_out[:m], k_out[:m]


@numba.njit(cache=True)
def _sees(speed, v0, hx, hy, px, py, qx, qy):
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


@numba.njit(cache=True)
def _unit_slope(field, i, j, hx, hy):
    """Direction of the finite-difference gradient of ``field`` at a node."""
    gx = _slope(field, i, j, 1, 0, hx)
    gy = _slope(field, i, j, 0, 1, hy)
    n = math.hypot(gx, gy)
    if n > 0.0:
        return gx / n, gy / n
    return 0.0, 0.0


@numba.njit(cache=True, error_model="numpy")
def _edge_terms(a, b, xa, xb, psi, psic, phi, speed, px, py, v0, vp, ex, ey, v0e, ve, hx, hy, rays):
    """Per boundary edge ``a -> b``: the boundary length it stands for, that
    length over ``|grad f|``, and the direction ``e`` in which the geodesic to
    the capture point leaves the pursuer (``missing`` where that point is
    hidden from the pursuer and ``rays`` is empty).

    Everything is taken at the edge's midpoint ``c`` and the midpoint ``X`` of
    the capture points of its ends. ``|grad psi^c| = 1 / (vp speed(X))`` and
    ``|grad phi| = 1 / (ve speed(c))`` exactly (the eikonal equation); only
    the directions of arrival come from geometry: the straight line from the
    agent where it sees the point, the finite-difference gradient where it
    does not. Differencing ``psi^c - phi`` directly would subtract two
    first-order fields whose difference is small (``|xi| / r`` on a bisector)
    and get its size wrong several times over far from the agents.

    An edge along x is crossed by a boundary of unit length ``|n_x| / hy``
    times, so it stands for ``hy |n_x|`` of it (``hx |n_y|`` along y): summed
    over both families, the boundary's length.
    """
    nx, ny = psi.shape
    m = a.size
    length = np.zeros(m)
    weight = np.zeros(m)
    e = np.zeros((m, 2))
    missing = np.zeros(m, dtype=np.bool_)
    have_rays = rays.shape[0] == nx
    for q in range(m):
        ai = a[q] // ny
        aj = a[q] - ai * ny
        bi = b[q] // ny
        bj = b[q] - bi * ny
        cx = 0.5 * (ai + bi) * hx
        cy = 0.5 * (aj + bj) * hy
        xai = xa[q] // ny
        xaj = xa[q] - xai * ny
        xbi = xb[q] // ny
        xbj = xb[q] - xbi * ny
        sx = 0.5 * (xai + xbi) * hx
        sy = 0.5 * (xaj + xbj) * hy
        # The pursuer's arrival direction at X, and whether X is in its sight.
        rp = math.hypot(sx - px, sy - py)
        seen_p = rp > 0.0 and _sees(speed, v0, hx, hy, px, py, sx, sy)
        if seen_p:
            upx = (sx - px) / rp
            upy = (sy - py) / rp
        else:
            upx, upy = _unit_slope(psi, xai, xaj, hx, hy)
        # The evader's.
        re = math.hypot(cx - ex, cy - ey)
        if re > 0.0 and _sees(speed, v0e, hx, hy, ex, ey, cx, cy):
            uex = (cx - ex) / re
            uey = (cy - ey) / re
        else:
            uex, uey = _unit_slope(phi, ai, aj, hx, hy)
        sp = 1.0 / (vp * speed[xai, xaj])
        se = 1.0 / (ve * speed[ai, aj])
        gx = sp * upx - se * uex
        gy = sp * upy - se * uey
        g = max(math.hypot(gx, gy), _FLAT * min(sp, se))
        if ai != bi:
            length[q] = hy * abs(gx) / g
            jump = abs(psic[bi, bj] - psic[ai, aj]) / hx
        else:
            length[q] = hx * abs(gy) / g
            jump = abs(psic[bi, bj] - psic[ai, aj]) / hy
        # psi^c steeper than any pursuer can climb: the capture disk stops
        # reaching through a wall between a and b, and the boundary stays
        # pinned there whatever the pursuer does.
        if jump <= _JUMP / (vp * min(speed[ai, aj], speed[bi, bj])):
            weight[q] = length[q] / g
        if seen_p:
            e[q, 0] = upx
            e[q, 1] = upy
        elif have_rays:
            dx = rays[xai, xaj, 0] + rays[xbi, xbj, 0]
            dy = rays[xai, xaj, 1] + rays[xbi, xbj, 1]
            n = math.hypot(dx, dy)
            if n > 0.0:
                e[q, 0] = dx / n
                e[q, 1] = dy / n
        else:
            missing[q] = True
    return length, weight, e, missing


@numba.njit(cache=True)
def _capture_points(psi, nodes, widths):
    """For each flat node, the flat index of the node of its capture disk the
    pursuer reaches first (``x*``, where ``psi^c`` takes its value)."""
    nx, ny = psi.shape
    m = widths.size - 1
    out = np.empty(nodes.size, dtype=np.int64)
    for q in range(nodes.size):
        i = nodes[q] // ny
        j = nodes[q] - i * ny
        best = np.inf
        arg = nodes[q]
        for di in range(-m, m + 1):
            a = i + di
            if a < 0 or a >= nx:
                continue
            w = widths[abs(di)]
            for dj in range(-w, w + 1):
                b = j + dj
                if b < 0 or b >= ny:
                    continue
                v = psi[a, b]
                if v < best:
                    best = v
                    arg = a * ny + b
        out[q] = arg
    return out


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
