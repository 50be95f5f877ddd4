"""Safe-reachable-area pursuit in a convex domain at equal speeds (thesis
5.2.1), pure pursuit, and the farthest-point evader of thesis 5.3.2.

With equal speeds in a convex domain the evader's safe-reachable set S_e is
its Voronoi cell clipped to the domain (5.2.1), so everything here is exact
plane geometry: the cell comes from clipping the domain by one half-plane
per pursuer (Sutherland-Hodgman), and each clip remembers which pursuer's
bisector made each edge, which is how the lines of control B_i and the
neighbour set N_e are read off without a second pass.

Gradients follow Lemma 3 in the local frame of each pursuer, with
``eta_h = xi / |xi|`` (``xi`` pursuer to evader) and ``eta_v`` = ``eta_h``
turned +90 degrees. ``l_i`` is the thesis's length of B_i on the side of
the foot of ``xi`` opposite ``eta_v``, taken *signed*: with s the
coordinate along ``eta_v`` measured from the foot (the midpoint of pursuer
and evader) and B_i spanning ``[s0, s1]``, ``l_i = -s0``. In the first case
of Lemma 3 (``xi`` crosses B_i) that is the plain length; in the second case
B_i lies wholly on one side and ``l_i`` is either ``>= L_i`` (B_i on the
``-eta_v`` side, the thesis's figure) or negative (B_i on the ``+eta_v``
side, which the thesis does not draw). The one formula
``D_v A = (l_i**2 - (L_i - l_i)**2) / (2 |xi_i|)`` then holds in every case.
Equivalently ``dA/dx_p^i = -(L_i / |xi_i|) (c_i - x_p^i)`` with c_i the
midpoint of B_i, so the area-minimising heading points at c_i, a point of
the domain: that is Lemma 4.

Speeds are 1 (the thesis rescales to that); headings are unit vectors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from bearcat.solvers.errors import InputError, non_negative

__all__ = [
    "AreaGradient",
    "ConvexAreaPursuit",
    "ConvexFarthestPointEvader",
    "StraightPursuit",
    "area_minimising_headings",
    "convex_area_gradient",
    "evader_area_gradient",
    "pure_pursuit_headings",
    "voronoi_cell",
]

# Lengths below this fraction of the domain's size count as zero: vertices
# closer than that are merged, and a bisector that only touches the cell
# gives its pursuer no line of control.
_MERGE = 1e-12
# How far outside the domain, as a fraction of its size, an agent may stand
# (round-off in a caller's step) before it is refused.
_OUTSIDE = 1e-9


@dataclass(frozen=True)
class AreaGradient:
    """The evader's cell and the first-order change of its area.

    ``area`` is |S_e| (eq. 5.8). ``gradient[i]`` is dA/dx_p^i (Lemma 3,
    eq. 5.10), a zero row for pursuers outside N_e; ``evader_gradient`` is
    dA/dx_e (eq. 5.12 summed over N_e). ``active[i]`` says pursuer i has a
    line of control B_i, of length ``line_length[i]``; ``line_split[i]`` is
    the thesis's l_i, signed as the module docstring explains (0 <= l_i <=
    L_i exactly when ``xi_i`` crosses B_i). ``vertices`` are the cell's
    corners, counter-clockwise; empty once a pursuer stands on the evader."""

    area: float
    gradient: np.ndarray
    evader_gradient: np.ndarray
    active: np.ndarray
    line_length: np.ndarray
    line_split: np.ndarray
    vertices: np.ndarray


# ---------------------------------------------------------------- kernels


@numba.njit(cache=True)
def _domain_status(domain):
    """0: convex and counter-clockwise, 1: convex and clockwise, 2: no area,
    3: not convex. Collinear corners are allowed."""
    m = domain.shape[0]
    twice_area = 0.0
    size = 0.0
    for k in range(m):
        a = domain[k - 1]
        b = domain[k]
        twice_area += a[0] * b[1] - b[0] * a[1]
        size = max(size, abs(b[0] - domain[0, 0]), abs(b[1] - domain[0, 1]))
    if not twice_area > 1e-12 * size * size and not twice_area < -1e-12 * size * size:
        return 2
    sign = 1.0 if twice_area > 0 else -1.0
    for k in range(m):
        a = domain[k - 2]
        b = domain[k - 1]
        c = domain[k]
        cross = (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])
        if sign * cross < -1e-12 * size * size:
            return 3
    return 0 if sign > 0 else 1


@numba.njit(cache=True)
def _size(domain):
    lo0, hi0, lo1, hi1 = domain[0, 0], domain[0, 0], domain[0, 1], domain[0, 1]
    for k in range(1, domain.shape[0]):
        lo0 = min(lo0, domain[k, 0])
        hi0 = max(hi0, domain[k, 0])
        lo1 = min(lo1, domain[k, 1])
        hi1 = max(hi1, domain[k, 1])
    return max(hi0 - lo0, hi1 - lo1)


@numba.njit(cache=True)
def _first_outside(domain, points, tol):
    """Index of the first point farther than ``tol`` outside the
    counter-clockwise convex ``domain``, or -1."""
    m = domain.shape[0]
    for j in range(points.shape[0]):
        for k in range(m):
            a = domain[k - 1]
            b = domain[k]
            ex, ey = b[0] - a[0], b[1] - a[1]
            length = np.hypot(ex, ey)
            if length == 0.0:
                continue
            # Positive to the right of a -> b, which is outside for a CCW polygon.
            if ((points[j, 0] - a[0]) * ey - (points[j, 1] - a[1]) * ex) / length > tol:
                return j
    return -1


@numba.njit(cache=True)
def _clip_cell(domain, evader, pursuers, merge):
    """The evader's cell and, for each vertex, who made the edge arriving at
    it: pursuer i >= 0 (its bisector) or -1 (the domain boundary)."""
    m = domain.shape[0]
    n = pursuers.shape[0]
    cap = m + n + 1  # a convex polygon gains at most one corner per clip
    poly = np.empty((cap, 2))
    labels = np.empty(cap, np.int64)
    spare = np.empty((cap, 2))
    spare_labels = np.empty(cap, np.int64)
    for k in range(m):
        poly[k] = domain[k]
        labels[k] = -1
    count = m
    for i in range(n):
        nx = pursuers[i, 0] - evader[0]
        ny = pursuers[i, 1] - evader[1]
        if nx == 0.0 and ny == 0.0:
            count = 0  # a pursuer on the evader leaves it nowhere to go
            break
        mx = 0.5 * (pursuers[i, 0] + evader[0])
        my = 0.5 * (pursuers[i, 1] + evader[1])
        out = 0
        p = poly[count - 1]
        sp = (p[0] - mx) * nx + (p[1] - my) * ny
        for k in range(count):
            q = poly[k]
            sq = (q[0] - mx) * nx + (q[1] - my) * ny
            if sq <= 0.0:
                if sp > 0.0:  # entering: the edge before this one runs along the bisector
                    t = sp / (sp - sq)
                    spare[out, 0] = p[0] + t * (q[0] - p[0])
                    spare[out, 1] = p[1] + t * (q[1] - p[1])
                    spare_labels[out] = i
                    out += 1
                spare[out] = q
                spare_labels[out] = labels[k]
                out += 1
            elif sp <= 0.0:  # leaving: keep the stretch of this edge that is inside
                t = sp / (sp - sq)
                spare[out, 0] = p[0] + t * (q[0] - p[0])
                spare[out, 1] = p[1] + t * (q[1] - p[1])
                spare_labels[out] = labels[k]
                out += 1
            p = q
            sp = sq
        poly, spare = spare, poly
        labels, spare_labels = spare_labels, labels
        count = out
        if count == 0:
            break
    # Merge coincident corners (a corner on a bisector yields its copy); the
    # zero-length edge between them, and whoever made it, disappear.
    kept = 0
    for k in range(count):
        if kept > 0 and np.hypot(poly[k, 0] - poly[kept - 1, 0], poly[k, 1] - poly[kept - 1, 1]) <= merge:
            continue
        poly[kept] = poly[k]
        labels[kept] = labels[k]
        kept += 1
    while kept > 1 and np.hypot(poly[0, 0] - poly[kept - 1, 0], poly[0, 1] - poly[kept - 1, 1]) <= merge:
        labels[0] = labels[kept - 1]
        kept -= 1
    if kept < 3:
        kept = 0
    return poly[:kept].copy(), labels[:kept].copy()


@numba.njit(cache=True)
def _area_gradient(domain, evader, pursuers, merge):
    vertices, labels = _clip_cell(domain, evader, pursuers, merge)
    n = pursuers.shape[0]
    k = vertices.shape[0]
    gradient = np.zeros((n, 2))
    evader_gradient = np.zeros(2)
    active = np.zeros(n, np.bool_)
    line_length = np.zeros(n)
    line_split = np.zeros(n)
    twice_area = 0.0
    for j in range(k):
        a = vertices[j - 1]
        b = vertices[j]
        twice_area += a[0] * b[1] - b[0] * a[1]
        i = labels[j]
        if i < 0:
            continue
        big_l = np.hypot(b[0] - a[0], b[1] - a[1])
        xi0 = evader[0] - pursuers[i, 0]
        xi1 = evader[1] - pursuers[i, 1]
        r = np.hypot(xi0, xi1)
        h0, h1 = xi0 / r, xi1 / r  # eta_h
        v0, v1 = -h1, h0  # eta_v: eta_h turned +90 degrees
        mx = 0.5 * (evader[0] + pursuers[i, 0])
        my = 0.5 * (evader[1] + pursuers[i, 1])
        sa = (a[0] - mx) * v0 + (a[1] - my) * v1
        sb = (b[0] - mx) * v0 + (b[1] - my) * v1
        small_l = -min(sa, sb)
        alpha_h = -0.5 * big_l
        # (l^2 - (L - l)^2) / (2 |xi|), factored to spare the cancellation.
        alpha_v = big_l * (2.0 * small_l - big_l) / (2.0 * r)
        gradient[i, 0] = alpha_h * h0 + alpha_v * v0
        gradient[i, 1] = alpha_h * h1 + alpha_v * v1
        evader_gradient[0] += alpha_h * h0 - alpha_v * v0
        evader_gradient[1] += alpha_h * h1 - alpha_v * v1
        active[i] = True
        line_length[i] = big_l
        line_split[i] = small_l
    return 0.5 * twice_area, gradient, evader_gradient, active, line_length, line_split, vertices


@numba.njit(cache=True)
def _pure_pursuit(evader, pursuers):
    n = pursuers.shape[0]
    out = np.zeros((n, 2))
    for i in range(n):
        d0 = evader[0] - pursuers[i, 0]
        d1 = evader[1] - pursuers[i, 1]
        r = np.hypot(d0, d1)
        if r > 0.0:
            out[i, 0] = d0 / r
            out[i, 1] = d1 / r
    return out


@numba.njit(cache=True)
def _headings(domain, evader, pursuers, merge):
    _, gradient, _, active, _, _, _ = _area_gradient(domain, evader, pursuers, merge)
    out = _pure_pursuit(evader, pursuers)
    for i in range(pursuers.shape[0]):
        if active[i]:
            g = np.hypot(gradient[i, 0], gradient[i, 1])
            if g > 0.0:  # eq. 5.11
                out[i, 0] = -gradient[i, 0] / g
                out[i, 1] = -gradient[i, 1] / g
    return out


# ---------------------------------------------------------------- checks


def _domain(domain) -> np.ndarray:
    """The domain as a contiguous CCW (m, 2) array; a closing repeat of the
    first vertex (shapely's rings) is dropped and clockwise input reversed."""
    d = np.asarray(domain, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 2:
        raise InputError(f"the domain must be an (m, 2) array of polygon vertices, got shape {d.shape}")
    if len(d) > 1 and d[0, 0] == d[-1, 0] and d[0, 1] == d[-1, 1]:
        d = d[:-1]
    if len(d) < 3 or not np.isfinite(d).all():
        raise InputError("the domain needs at least three finite vertices")
    d = np.ascontiguousarray(d)
    status = _domain_status(d)
    if status == 1:
        return np.ascontiguousarray(d[::-1])
    if status == 2:
        raise InputError("the domain polygon has no area")
    if status == 3:
        raise InputError("the domain polygon is not convex; the convex pursuit of thesis 5.2.1 needs a convex one")
    return d


def _agents(domain: np.ndarray, evader, pursuers) -> tuple[np.ndarray, np.ndarray]:
    e = np.ascontiguousarray(evader, dtype=np.float64)
    p = np.ascontiguousarray(pursuers, dtype=np.float64)
    if e.shape != (2,) or not np.isfinite(e).all():
        raise InputError(f"the evader must be one finite point (x, y), got {evader!r}")
    if p.ndim != 2 or p.shape[1] != 2 or len(p) == 0 or not np.isfinite(p).all():
        raise InputError(f"the pursuers must be a non-empty (N, 2) array of finite points, got shape {p.shape}")
    tol = _OUTSIDE * _size(domain)
    if _first_outside(domain, e.reshape(1, 2), tol) >= 0:
        raise InputError(f"the evader at ({e[0]:.3f}, {e[1]:.3f}) is outside the domain")
    j = _first_outside(domain, p, tol)
    if j >= 0:
        raise InputError(f"pursuer {j} at ({p[j, 0]:.3f}, {p[j, 1]:.3f}) is outside the domain")
    return e, p


# ---------------------------------------------------------------- public


def voronoi_cell(domain, evader, pursuers) -> np.ndarray:
    """Corners (k, 2), counter-clockwise, of S_e: the points of the convex
    ``domain`` nearer the evader than every pursuer. Empty (0, 2) if a
    pursuer stands on the evader."""
    d = _domain(domain)
    e, p = _agents(d, evader, pursuers)
    return _clip_cell(d, e, p, _MERGE * _size(d))[0]


def line_of_control(domain, evader, pursuers, k: int) -> np.ndarray:
    """Pursuer ``k``'s stretch of the boundary of S_e (its line of control,
    5.3.1): the two ends (2, 2), or (0, 2) if its bisector does not bound
    S_e. Read from the clip that made the cell, not by measuring distances
    afterwards, which rounding makes unreliable."""
    d = _domain(domain)
    e, p = _agents(d, evader, pursuers)
    if not 0 <= k < p.shape[0]:
        raise InputError(f"there is no pursuer {k}: the pursuers are 0 to {p.shape[0] - 1}")
    cell, owners = _clip_cell(d, e, p, _MERGE * _size(d))
    for j in range(cell.shape[0]):
        if owners[j] == k:  # the edge arriving at corner j runs along pursuer k's bisector
            return np.array([cell[j - 1], cell[j]])
    return np.empty((0, 2))


def convex_area_gradient(domain, evader, pursuers) -> AreaGradient:
    """|S_e| and its derivatives in every agent's position (Lemma 3, eq. 5.12)."""
    d = _domain(domain)
    e, p = _agents(d, evader, pursuers)
    return AreaGradient(*_area_gradient(d, e, p, _MERGE * _size(d)))


def evader_area_gradient(domain, evader, pursuers) -> np.ndarray:
    """dA/dx_e (2,): eq. 5.12, one term ``alpha_h eta_h - alpha_v eta_v``
    per line of control; its direction is the evader's best reply gamma*
    (eq. 5.14)."""
    return convex_area_gradient(domain, evader, pursuers).evader_gradient


def pure_pursuit_headings(evader, pursuers) -> np.ndarray:
    """(N, 2) unit vectors from each pursuer to the evader; a zero row for a
    pursuer standing on it."""
    e = np.ascontiguousarray(evader, dtype=np.float64)
    p = np.ascontiguousarray(pursuers, dtype=np.float64)
    if e.shape != (2,) or p.ndim != 2 or p.shape[1] != 2:
        raise InputError("the evader must be one point (x, y) and the pursuers an (N, 2) array")
    return _pure_pursuit(e, p)


def area_minimising_headings(domain, evader, pursuers) -> np.ndarray:
    """(N, 2) unit headings: down the area gradient (eq. 5.11) for pursuers
    with a line of control, straight at the evader for the others (5.3.1)."""
    d = _domain(domain)
    e, p = _agents(d, evader, pursuers)
    return _headings(d, e, p, _MERGE * _size(d))


class ConvexAreaPursuit:
    """The cooperative pursuit of thesis 5.2.1 as a strategy object; the
    domain is checked once here rather than at every step."""

    def __init__(self, domain) -> None:
        self.domain = _domain(domain)
        self._merge = _MERGE * _size(self.domain)

    def headings(self, evader, pursuers) -> np.ndarray:
        e, p = _agents(self.domain, evader, pursuers)
        return _headings(self.domain, e, p, self._merge)


class StraightPursuit:
    """Pure pursuit, the thesis's baseline: every pursuer heads straight at the evader."""

    def headings(self, evader, pursuers) -> np.ndarray:
        return pure_pursuit_headings(evader, pursuers)


class ConvexFarthestPointEvader:
    """The evader of the comparison tests (5.3.2): it runs for y*, the point
    of its safe-reachable set farthest from it, and only picks a new y* once
    within half the capture radius of the old one, even if the pursuers have
    since taken y* away. In a convex domain the geodesic distance is the
    straight one, whose maximum over the convex cell sits at a corner.

    Stateful: ``target`` is the current y* (None before the first call)."""

    def __init__(self, domain, capture_radius: float) -> None:
        self.domain = _domain(domain)
        self.capture_radius = non_negative(capture_radius, "the capture radius")
        self.target: np.ndarray | None = None
        self._merge = _MERGE * _size(self.domain)

    def heading(self, evader, pursuers) -> np.ndarray:
        e, p = _agents(self.domain, evader, pursuers)
        if self.target is None or np.hypot(*(self.target - e)) <= 0.5 * self.capture_radius:
            cell = _clip_cell(self.domain, e, p, self._merge)[0]
            if len(cell):
                self.target = cell[np.argmax(np.hypot(*(cell - e).T))].copy()
        if self.target is None:
            return np.zeros(2)
        to_target = self.target - e
        distance = float(np.hypot(*to_target))
        return to_target / distance if distance > self._merge else np.zeros(2)
