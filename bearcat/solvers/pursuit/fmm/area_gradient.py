"""``dA/dx_p``: how the area ``A`` of the evader's safe-reachable set ``S_e``
changes as each pursuer moves (thesis 5.2.2), by one of two methods.

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

``e`` is known exactly where the pursuer sees the point in a straight line
at its own speed (the direction to the point) and is carried along the rays
elsewhere (``rays.first_steps``). ``|grad f|`` takes the sizes of
``grad psi^c`` and ``grad phi`` from the eikonal equation (one over the local
speed) and their directions from the geometry: the straight line from an
agent that sees the point, the finite-difference gradient of its front
otherwise. Differencing the two first-order fields instead gets ``|grad f|``
wrong several times over where it is small (``|xi| / r`` on a bisector, far
from close agents).

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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from bearcat.solvers.marching import fmm
from bearcat.solvers.pursuit.fmm.rays import sees
from bearcat.solvers.pursuit.fmm.safe_set import SafeSet, check_pursuer_speeds, march_safe_set
from bearcat.solvers.pursuit.fmm.travel_times import TravelTimes

__all__ = ["METHODS", "AreaGradient", "area_gradient"]

METHODS = ("boundary", "finite")
_MIN_ACTIVE_CELLS = 2.0  # an active boundary shorter than this many spacings is junction noise
_FLAT = 0.01  # floor of |grad f| as a fraction of the smaller slowness (module notes)
_JUMP = 2.5  # psi^c steeper than this many slownesses across an edge is a jump (module notes)


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


def area_gradient(
    travel_times: TravelTimes, e: np.ndarray, ps: np.ndarray, ve: float, speeds, radius: float, method: str
) -> AreaGradient:
    """``dA/dx_p`` of every pursuer by ``method`` (one of ``METHODS``), for
    inputs checked as ``march_safe_set`` takes them; ``speeds`` is one
    pursuer speed or one per pursuer."""
    n = len(ps)
    speeds = check_pursuer_speeds(speeds, n)
    safe = march_safe_set(travel_times, e, ps, ve, speeds, radius)
    a, b, owner = _boundary_edges(travel_times, safe)
    length = np.zeros(n)
    bounds: dict[int, _Boundary] = {}
    for k in map(int, np.unique(owner)):
        sel = owner == k
        bounds[k] = _Boundary(travel_times, e, k, ps[k], speeds[k], ve, radius, safe, a[sel], b[sel])
        length[k] = bounds[k].length.sum()
    active = length >= _MIN_ACTIVE_CELLS * max(travel_times.spacing)
    grad = np.zeros((n, 2))
    for k in map(int, np.flatnonzero(active)):
        if method == "boundary":
            grad[k] = bounds[k].gradient()
        else:
            grad[k] = _finite_gradient(travel_times, e, ps, speeds, k, ve, radius)
    for x in (grad, active, length):
        x.flags.writeable = False
    return AreaGradient(safe=safe, gradient=grad, active=active, boundary_length=length)


def _boundary_edges(travel_times: TravelTimes, safe: SafeSet):
    """Grid edges from a node ``a`` of ``S_e`` to a free node ``b`` outside it,
    and the pursuer that cut ``b`` off (flat indices)."""
    if len(safe.pursuer_times) == 0 or not safe.mask.any():
        z = np.zeros(0, dtype=np.int64)
        return z, z, z
    return _edges(safe.mask, travel_times.free, safe.owner)


class _Boundary:
    """Pursuer ``k``'s part of the boundary: per edge the boundary length it
    stands for, that length over ``|grad f|``, and ``e(x*)`` (module notes)."""

    def __init__(self, travel_times: TravelTimes, e, k: int, p, speed, ve: float, radius: float, safe: SafeSet, a, b):
        # a, b: the flat nodes of pursuer k's edges, inside and outside S_e.
        self.front = travel_times.front(p)
        self.speed = float(speed)
        (lx, ly), (hx, hy) = travel_times.lo, travel_times.spacing
        widths = fmm.disk_widths(radius, hx, hy)
        self.xa = _capture_points(self.front.times, a, widths)
        self.xb = _capture_points(self.front.times, b, widths)
        self._args = (
            a,
            b,
            self.xa,
            self.xb,
            self.front.times,
            safe.pursuer_times[k],
            safe.evader_time,
            travel_times.speed,
            p[0] - lx,
            p[1] - ly,
            self.front.source_speed,
            self.speed,
            e[0] - lx,
            e[1] - ly,
            travel_times.source_speed(e),
            float(ve),
            hx,
            hy,
        )
        self.length, self.weight, self.e, self.missing = _edge_terms(*self._args, _NO_RAYS)

    def gradient(self) -> np.ndarray:
        """``dA/dx_p = -(1 / v) sum weight * e``, ``v`` the pursuer's speed where it stands."""
        if self.missing.any():
            # Some capture points are out of the pursuer's sight: carry the directions there.
            flat = self.front.times.ravel()
            limit = float(max(flat[self.xa].max(), flat[self.xb].max()))
            rays = self.front.first_steps(limit)
            self.length, self.weight, self.e, self.missing = _edge_terms(*self._args, rays)
        v = self.speed * self.front.source_speed
        return -(self.weight[:, None] * self.e).sum(axis=0) / v


_NO_RAYS = np.zeros((0, 0, 2))


def _finite_gradient(travel_times: TravelTimes, e, ps, speeds, k: int, ve: float, radius: float) -> np.ndarray:
    """One-cell forward differences of ``N_s h^2`` along x and y (thesis
    5.2.2); backward where the forward node is blocked, zero where both are."""
    safe = march_safe_set(travel_times, e, ps, ve, speeds, radius)
    grad = np.zeros(2)
    for axis in (0, 1):
        h = travel_times.spacing[axis]
        for sign in (1.0, -1.0):
            q = ps.copy()
            q[k, axis] += sign * h
            if not travel_times.placeable(q[k]):
                continue
            moved = march_safe_set(travel_times, e, q, ve, speeds, radius, keep=False)
            grad[axis] = sign * (moved.area - safe.area) / h
            break
    return grad


# ---------------------------------------------------------------------- kernels


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
def _ends(ka, kb, ny, hx, hy):
    """The nodes of flat indices ``ka`` and ``kb`` and their midpoint (metres from the first node)."""
    ai = ka // ny
    aj = ka - ai * ny
    bi = kb // ny
    bj = kb - bi * ny
    return ai, aj, bi, bj, 0.5 * (ai + bi) * hx, 0.5 * (aj + bj) * hy


@numba.njit(cache=True)
def _arrival(field, speed, v0, hx, hy, px, py, qx, qy, i, j):
    """The direction in which the front ``field`` of an agent at ``p`` arrives
    at ``q`` (node ``(i, j)`` or beside it), and whether ``q`` is in the
    agent's sight: the straight line from ``p`` there, the finite-difference
    gradient of ``field`` at the node elsewhere."""
    r = math.hypot(qx - px, qy - py)
    if r > 0.0 and sees(speed, v0, hx, hy, px, py, qx, qy):
        return (qx - px) / r, (qy - py) / r, True
    ux, uy = _unit_slope(field, i, j, hx, hy)
    return ux, uy, False


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
        ai, aj, bi, bj, cx, cy = _ends(a[q], b[q], ny, hx, hy)
        xai, xaj, xbi, xbj, sx, sy = _ends(xa[q], xb[q], ny, hx, hy)
        # The pursuer's arrival direction at X, and whether X is in its sight; the evader's at c.
        upx, upy, seen_p = _arrival(psi, speed, v0, hx, hy, px, py, sx, sy, xai, xaj)
        uex, uey, _ = _arrival(phi, speed, v0e, hx, hy, ex, ey, cx, cy, ai, aj)
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
