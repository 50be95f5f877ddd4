"""Reachability-guided UAV search in the limited-visibility flag-return game (thesis 6.2).

The attacking side (the attacker and its UAV) has lost sight of the
defender. ``visibility`` and ``footprint`` give what each of them sees
(``V_A``, ``V_Q``; ``V_J = V_A | V_Q``), ``PossibleDefender`` tracks ``P_D``,
where the defender may be, and ``search_target`` picks the UAV's next point
by the hierarchy of eqs. 6.7-6.9. ``lawnmower`` and ``nearest_unobserved`` are
the baselines a study compares it with.

Readings of the thesis where it leaves a choice:

- ``P_D`` grows by the defender's reach over the step through free space,
  seen or not, and then loses what is seen at the step's end. Sensing is
  sampled (the referee looks at each tick, as the 6.2.4 trials simulated
  it), so a defender that is unseen at both ends of a step may have crossed
  ground that was seen at both: blocking growth on that ground would lose a
  defender that sprints across a thin seen band, or one that steps out of
  view right after being found, whose found position is still seen. What
  this costs is that ``P_D`` can hop a seen band narrower than ``v_d dt``
  (plus up to a cell); a shorter step makes that band thinner.
- ``S_D`` takes the UAV to see a point once the point is within ``r_q`` of
  it, the capture radius of thesis 4.1.3: ``(|x - x_q| - r_q)^+ / v_q``,
  flying straight over buildings.
- The tiers search ``S_D`` *intersected* with ``RA(Z, V_J)`` (then with
  ``RA(Z~, V_J)``, then ``S_D`` alone). Eqs. 6.7-6.8 write a union, but
  with a union the first tier is non-empty whenever ``S_D`` is, the later
  tiers could never be reached, and targets could fall where the defender
  cannot be; the prose ("search the set of defender positions that may reach
  Z without being seen") is the intersection. Eq. 6.8's ``psi_Z`` is read as
  ``psi_Z~``.
- ``psi_Z``, ``psi_Z~`` and ``psi_delta`` are distances a defender walks
  (metres at full speed, so slow terrain counts longer): to ``Z`` or ``Z~``
  through unseen free space, and to the attacker through any free space, as
  the danger is how soon a defender there could reach the attacker.
  ``psi_Q`` is the straight distance to the UAV. A node from which the
  attacker cannot be reached at all is no threat and is never a target.

Arrays are indexed ``[ix, iy]`` (x east, y north) on a ``solvers.grid.Grid``;
``terrain`` is the speed factor per node (0 where blocked), as
``maps.Raster.speed`` gives it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from bearcat.solvers.errors import InputError, non_negative, positive
from bearcat.solvers.grid import Grid
from bearcat.solvers.marching import fmm

__all__ = [
    "PossibleDefender",
    "SearchTarget",
    "Weights",
    "footprint",
    "lawnmower",
    "nearest_unobserved",
    "search_target",
    "visibility",
]

# --------------------------------------------------------------------------- visibility


def visibility(free, grid: Grid, point, max_range: float = math.inf) -> np.ndarray:
    """``V_A``: the free nodes in line of sight of ``point`` within ``max_range`` metres.

    A node is seen when the straight line to it crosses only free nodes,
    sampled once per row or column along its longer axis and rounded to the
    nearest node (so a wall one node thick and exactly diagonal can leak).
    The viewer's own node never blocks: a position fix a little inside a wall
    still sees out. Shadows are exact up to the raster: the edge of a shadow
    can be off by the angle half a cell subtends at the corner casting it.
    """
    free = _mask(free, grid, "free")
    p = _point(grid, point, "viewer")
    max_range = non_negative(max_range, "max_range", finite=False)
    fx, fy = grid.fractional_index(p)
    hx, hy = grid.spacing
    return _visible(free, float(fx), float(fy), float(hx), float(hy), max_range)


def footprint(grid: Grid, uav_xy, r_q: float) -> np.ndarray:
    """``V_Q``: the nodes within ``r_q`` of the UAV, which looks straight down
    over buildings. The UAV may be off the grid (its footprint then covers
    what overlaps)."""
    return _distance_from(grid, _xy(uav_xy, "UAV")) <= non_negative(r_q, "footprint radius")


# --------------------------------------------------------------------------- P_D


class PossibleDefender:
    """``P_D``, the nodes the defender may occupy unseen (thesis 6.2.3).

    Besides the mask it keeps, per node, how far (metres) the front of
    possible positions has already passed it, so that growth shorter than a
    cell per step still adds up. The lead stops at one spacing, where the
    front has moved on to the next node: a node the front passed long ago
    would otherwise flood ground that was seen and is unseen again as if the
    defender had been walking into it all along (with the cap it overshoots
    by at most a cell, on the safe side). Not thread-safe; one per game.
    """

    def __init__(self, terrain, grid: Grid, region, *, seen=None) -> None:
        """``P_D^0`` = the free, unseen nodes of the boolean ``region``
        (``terrain > 0`` for "anywhere")."""
        self.grid = grid
        self._terrain = _terrain(terrain, grid)
        self._cap = float(max(grid.spacing))
        region = _mask(region, grid, "region")
        self._lead = np.where(region, 0.0, -np.inf)
        self._keep(seen)

    @classmethod
    def around(cls, terrain, grid: Grid, center, radius: float, *, seen=None) -> PossibleDefender:
        """``P_D^0`` = the disk of ``radius`` metres around the defender's last
        known or prior position, with its edge placed between nodes."""
        pd = cls(terrain, grid, np.zeros(grid.shape, dtype=bool))
        pd._lead = _disk_lead(grid, _point(grid, center, "defender"), non_negative(radius, "P_D radius"))
        pd._keep(seen)
        return pd

    @property
    def mask(self) -> np.ndarray:
        """``P_D`` as a boolean array over the grid (a fresh copy)."""
        return self._lead >= 0

    @property
    def area(self) -> float:
        """Square metres: nodes times the cell area."""
        return float(np.count_nonzero(self._lead >= 0)) * self.grid.cell_area

    def advance(self, dt: float, v_d: float, seen) -> None:
        """Let ``dt`` seconds pass with the defender moving at up to ``v_d``
        m/s (times the terrain factor), then drop ``seen`` (``V_J`` at the end
        of the step); see the module notes for why growth crosses ground
        seen at both ends of the step."""
        dt = non_negative(dt, "time step")
        v_d = positive(v_d, "defender speed")
        seen = _mask(seen, self.grid, "seen")
        # Times are shifted by one cap so every seed is >= 0: a node the front
        # passed ``lead`` metres ago starts at (cap - lead) / v_d.
        shift = self._cap / v_d
        initial = np.where(self._lead >= 0, (self._cap - self._lead) / v_d, np.inf)
        horizon = (shift + dt) * (1 + 1e-12) + 1e-12
        hx, hy = self.grid.spacing
        t = fmm.march(v_d * self._terrain, hx, hy, initial, np.full(self.grid.shape, horizon))
        self._lead = np.where(t < np.inf, np.minimum(v_d * (shift + dt - t), self._cap), -np.inf)
        self._lead[self._lead < 0] = -np.inf  # past the ceiling's rounding slack
        self._lead[seen] = -np.inf

    def found(self, point, radius: float = 0.0) -> None:
        """The defender was seen at ``point`` (within ``radius`` metres): ``P_D``
        collapses onto it, seen though it is, and grows from there."""
        self._lead = _disk_lead(self.grid, _point(self.grid, point, "defender"), non_negative(radius, "found radius"))
        self._keep(None)

    def _keep(self, seen) -> None:
        self._lead[self._terrain <= 0] = -np.inf
        if seen is not None:
            self._lead[_mask(seen, self.grid, "seen")] = -np.inf


def _disk_lead(grid: Grid, center: np.ndarray, radius: float) -> np.ndarray:
    """How far a front that fills the disk has passed each node; the nodes of
    the cell holding the centre always count, so a small disk is not empty."""
    lead = radius - _distance_from(grid, center)
    fi = np.floor(grid.fractional_index(center)).astype(int)
    i = np.clip([fi[0], fi[0] + 1], 0, grid.shape[0] - 1)
    j = np.clip([fi[1], fi[1] + 1], 0, grid.shape[1] - 1)
    corners = np.ix_(i, j)
    lead[corners] = np.maximum(lead[corners], 0.0)
    return np.where(lead >= 0, np.minimum(lead, max(grid.spacing)), -np.inf)


# --------------------------------------------------------------------------- the search target


@dataclass(frozen=True)
class Weights:
    """Weights of eqs. 6.7-6.9 on distances in metres; 6.2.4 flew with
    ``uav = 100`` and the rest 1, which makes the UAV sweep greedily along
    ``P_D`` instead of leaving pockets behind that grow back."""

    z: float = 1.0
    z_tilde: float = 1.0
    attacker: float = 1.0
    uav: float = 100.0

    def __post_init__(self) -> None:
        for name in ("z", "z_tilde", "attacker", "uav"):
            object.__setattr__(self, name, non_negative(getattr(self, name), f"weight {name}"))


@dataclass(frozen=True, eq=False)
class SearchTarget:
    """Where the UAV should search next, and the sets that chose it (boolean
    masks over the grid, for display).

    ``target`` is the chosen node in metres, ``tier`` the rule that chose
    it (1, 2, 3 for eqs. 6.7, 6.8, 6.9; 0 and no target when no node of
    ``S_D`` can reach the attacker) and ``cost`` its ``w_tier``.
    ``candidates`` is the set the argmin ran over.
    """

    target: tuple[float, float] | None
    tier: int
    cost: float
    s_d: np.ndarray
    z: np.ndarray
    z_tilde: np.ndarray
    reach_z: np.ndarray
    reach_z_tilde: np.ndarray
    candidates: np.ndarray


def search_target(
    terrain,
    grid: Grid,
    possible,
    seen_attacker,
    seen_uav,
    defender_wins,
    *,
    attacker,
    uav,
    defender_speed: float,
    uav_speed: float,
    uav_radius: float,
    weights: Weights = Weights(),
) -> SearchTarget:
    """The UAV's search target by the hierarchy of thesis 6.2.3.

    ``possible`` is ``P_D``, ``seen_attacker`` ``V_A``, ``seen_uav`` ``V_Q``
    and ``defender_wins`` ``W_D(x_a)`` (for instance
    ``Guidance.defender_region(x_a, "return")``), all boolean over the grid.
    ``S_D`` is the modified fast marching method: the defender's front from
    ``P_D`` through unseen free space, stopped where the UAV would see the
    node first. Then, over ``S_D`` nodes from which the attacker can be
    reached: those that reach ``Z = W_D & V_A`` unseen, by
    ``w_Z psi_Z + w_delta psi_delta + w_q psi_Q``; if none, those that reach
    ``Z~ = W_D - V_J`` unseen, with ``w_Z~`` on ``psi_Z~``; if none, all of
    them by ``w_delta psi_delta + w_q psi_Q``.
    """
    terrain = _terrain(terrain, grid)
    possible = _mask(possible, grid, "possible")
    seen_attacker = _mask(seen_attacker, grid, "seen_attacker")
    seen_uav = _mask(seen_uav, grid, "seen_uav")
    defender_wins = _mask(defender_wins, grid, "defender_wins")
    attacker = _point(grid, attacker, "attacker")
    uav = _xy(uav, "UAV")
    defender_speed = positive(defender_speed, "defender speed")
    uav_speed = positive(uav_speed, "UAV speed")
    uav_radius = non_negative(uav_radius, "UAV footprint radius")

    hx, hy = grid.spacing
    free = terrain > 0
    unseen = free & ~(seen_attacker | seen_uav)
    psi_q = _distance_from(grid, uav)
    uav_time = np.maximum(psi_q - uav_radius, 0.0) / uav_speed
    seeds = np.where(possible & unseen, 0.0, np.inf)
    s_d = np.isfinite(fmm.march(defender_speed * terrain * unseen, hx, hy, seeds, uav_time))
    psi_delta = fmm.march(terrain, hx, hy, fmm.point_source(grid, attacker, terrain))
    threats = s_d & np.isfinite(psi_delta)

    z = defender_wins & seen_attacker & free
    z_tilde = defender_wins & unseen
    psi_z = _unseen_distance(terrain, unseen, z, hx, hy)
    psi_z_tilde = _unseen_distance(terrain, unseen, z_tilde, hx, hy)
    reach_z = np.isfinite(psi_z)
    reach_z_tilde = np.isfinite(psi_z_tilde)

    w = weights
    near = w.attacker * psi_delta + w.uav * psi_q
    tiers = (
        (1, threats & reach_z, w.z * psi_z + near),
        (2, threats & reach_z_tilde, w.z_tilde * psi_z_tilde + near),
        (3, threats, near),
    )
    tier, candidates, cost = next(((k, c, w_k) for k, c, w_k in tiers if c.any()), (0, threats, near))
    target, best = _argmin(grid, candidates, cost)
    return SearchTarget(target, tier, best, s_d, z, z_tilde, reach_z, reach_z_tilde, candidates)


def _unseen_distance(terrain, unseen, targets, hx, hy) -> np.ndarray:
    """Distance to ``targets`` walking only through unseen free space (the
    targets themselves may be seen: ``Z`` lies in ``V_A``)."""
    seeds = np.where(targets, 0.0, np.inf)
    return fmm.march(terrain * (unseen | targets), hx, hy, seeds)


def _argmin(grid: Grid, candidates, cost) -> tuple[tuple[float, float] | None, float]:
    if not candidates.any():
        return None, math.inf
    masked = np.where(candidates, cost, np.inf)
    k = np.unravel_index(int(np.argmin(masked)), grid.shape)
    x, y = grid.point(k)
    return (float(x), float(y)), float(masked[k])


# --------------------------------------------------------------------------- baselines


def nearest_unobserved(grid: Grid, possible, uav) -> tuple[float, float] | None:
    """Baseline: the node of ``P_D`` nearest the UAV in a straight line (None if ``P_D`` is empty)."""
    possible = _mask(possible, grid, "possible")
    target, _ = _argmin(grid, possible, _distance_from(grid, _xy(uav, "UAV")))
    return target


def lawnmower(bounds, r_q: float, start=None) -> np.ndarray:
    """Baseline: a boustrophedon over the box ``(xmin, ymin, xmax, ymax)``,
    tracks ``2 r_q`` apart along its longer side, which a footprint of
    radius ``r_q`` covers without gaps (tracks run to the box's edges so the
    corners are covered too). Starts at the corner of the pattern nearest
    ``start``. Waypoints (n, 2) in metres, in flying order.
    """
    xmin, ymin, xmax, ymax = (float(v) for v in bounds)
    if not (all(math.isfinite(v) for v in (xmin, ymin, xmax, ymax)) and xmin < xmax and ymin < ymax):
        raise InputError(f"bounds must be finite (xmin, ymin, xmax, ymax) with min < max, got {bounds!r}")
    r_q = positive(r_q, "footprint radius")
    along_x = (xmax - xmin) >= (ymax - ymin)
    (a0, a1), (c0, c1) = ((xmin, xmax), (ymin, ymax)) if along_x else ((ymin, ymax), (xmin, xmax))
    count = max(1, math.ceil((c1 - c0) / (2 * r_q)))
    across = np.minimum(c0 + r_q * (2 * np.arange(count) + 1), max(c1 - r_q, (c0 + c1) / 2))
    ends = np.array([a0, a1])
    rows = [np.column_stack([ends if k % 2 == 0 else ends[::-1], [c, c]]) for k, c in enumerate(across)]
    path = np.vstack(rows)
    if not along_x:
        path = path[:, ::-1]
    if start is not None:
        path = _from_nearest_corner(path, _xy(start, "start"), (xmin, ymin, xmax, ymax))
    return path


def _from_nearest_corner(path, start, bounds) -> np.ndarray:
    """The pattern mirrored so that it begins at the corner nearest ``start``."""
    xmin, ymin, xmax, ymax = bounds
    options = []
    for flip_x in (False, True):
        for flip_y in (False, True):
            p = path.copy()
            if flip_x:
                p[:, 0] = xmin + xmax - p[:, 0]
            if flip_y:
                p[:, 1] = ymin + ymax - p[:, 1]
            options.append(p)
    return min(options, key=lambda p: float(np.hypot(*(p[0] - start))))


# --------------------------------------------------------------------------- helpers


def _mask(a, grid: Grid, name: str) -> np.ndarray:
    a = np.asarray(a)
    if a.shape != grid.shape:
        raise InputError(f"{name} has shape {a.shape} but the grid has shape {grid.shape}")
    return a.astype(bool, copy=False)


def _terrain(terrain, grid: Grid) -> np.ndarray:
    t = np.asarray(terrain, dtype=np.float64)
    if t.shape != grid.shape:
        raise InputError(f"terrain has shape {t.shape} but the grid has shape {grid.shape}")
    if not (np.isfinite(t) & (t >= 0)).all():
        raise InputError("terrain has a negative, NaN or infinite speed factor")
    return t


def _xy(point, who: str) -> np.ndarray:
    p = np.asarray(point, dtype=np.float64)
    if p.shape != (2,) or not np.isfinite(p).all():
        raise InputError(f"{who} position must be a finite (x, y) point, got {point!r}")
    return p


def _point(grid: Grid, point, who: str) -> np.ndarray:
    """A point that must lie on the grid: a viewer, the attacker, the defender."""
    p = _xy(point, who)
    if not grid.contains(p):
        (xmin, ymin), (xmax, ymax) = grid.lo, grid.hi
        raise InputError(f"{who} at ({p[0]:g}, {p[1]:g}) is off the grid [{xmin:g}, {xmax:g}] x [{ymin:g}, {ymax:g}]")
    return p


def _distance_from(grid: Grid, p: np.ndarray) -> np.ndarray:
    x, y = grid.axes()
    return np.hypot(x[:, None] - p[0], y[None, :] - p[1])


@numba.njit(cache=True, nogil=True)
def _visible(free, px, py, hx, hy, max_range):
    nx, ny = free.shape
    out = np.zeros((nx, ny), dtype=np.bool_)
    for ix in range(nx):
        dx = (ix - px) * hx
        for iy in range(ny):
            if free[ix, iy] and math.hypot(dx, (iy - py) * hy) <= max_range:
                out[ix, iy] = _clear(free, px, py, ix, iy)
    return out


@numba.njit(cache=True, inline="always")
def _clear(free, px, py, ix, iy):
    """Whether the line from node ``(ix, iy)`` back to the viewer at
    fractional index ``(px, py)`` crosses only free nodes; samples within
    half a cell of the viewer are its own node and are skipped."""
    dx = ix - px
    dy = iy - py
    if abs(dx) >= abs(dy):
        if dx == 0.0:
            return True
        step = 1 if dx > 0 else -1
        slope = dy / dx
        c = ix - step
        while (c - px) * step >= 0.5:
            if not free[c, int(math.floor(py + (c - px) * slope + 0.5))]:
                return False
            c -= step
    else:
        step = 1 if dy > 0 else -1
        slope = dx / dy
        c = iy - step
        while (c - py) * step >= 0.5:
            if not free[int(math.floor(px + (c - py) * slope + 0.5)), c]:
                return False
            c -= step
    return True
