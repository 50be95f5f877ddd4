"""Queries on a solved capture-the-flag game: what the phones of thesis 3.5
showed, answered for the current positions.

For a state ``(x_a, x_d)`` and the phase of play (``"capture"`` until the
attacker holds the flag, ``"return"`` after), ``CtfQueries`` gives the value
(the margin, in metres: negative where the attacker wins), the winner, each
side's optimal heading (eqs. 3.12-3.13 from the value's gradient) and the
opponent's winning region on the map: ``R_D(x_a)``, the defender positions
that win against the attacker where it stands, and ``R_A(x_d)``, the
attacker positions that win against the defender (Fig. 3.6, 3.9). Regions
come as a 2-D mask on the grid of one player and as polygons in map metres
traced at the zero level of the interpolated value, so their edges sit
between nodes.

Values are multilinear in the 4-D grid; gradients are central differences
at the nodes (one-sided on the edges), interpolated the same way, which
keeps headings continuous inside a cell. A state off the grid or inside an
obstacle is refused rather than extrapolated.

Sets of a local solve (``solve_ctf(..., local=True)``) answer every query
the same but where the defender wins by more than a few cells: there the
value is clamped at the solve's ceiling, so the margin reads "at least
that", and, the value being flat, both headings are None, as the phones
show where no direction is better than another. Winners, regions,
polygons, the margin near the boundary and every heading inside the
attacker's set (from T*) are those of the full grid.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import contourpy
import numba
import numpy as np
import shapely

from bearcat.solvers.ctf.sets import EDGE_SLACK, CtfGeometry, CtfSolution, Rules, SetSolution
from bearcat.solvers.errors import InputError
from bearcat.solvers.grid import Grid

if TYPE_CHECKING:
    from contourpy._contourpy import FillReturn_OuterOffset

__all__ = ["PHASES", "CtfQueries", "StateReport", "compile_kernels"]

PHASES = ("capture", "return")


@dataclass(frozen=True)
class StateReport:
    """The game at one state. ``value`` <= 0: the attacker wins with optimal
    play. Headings are unit vectors (east, north), None where the value is
    flat and no direction is better than another."""

    value: float
    attacker_heading: tuple[float, float] | None
    defender_heading: tuple[float, float] | None

    @property
    def winner(self) -> str:
        return "attacker" if self.value <= 0 else "defender"


class CtfQueries:
    """Queries on one solved game; cheap enough to answer every player ten
    times a second (see ``benchmarks/hji.py``)."""

    def __init__(self, solution: CtfSolution) -> None:
        self.solution = solution
        self.geometry = solution.geometry
        grid = self.geometry.grid
        self._lo = np.asarray(grid.lo * 2, np.float64)
        self._spacing = np.asarray(grid.spacing * 2, np.float64)
        self._axes = grid.axes()
        mesh_x, mesh_y = np.meshgrid(*self._axes)  # the nodes as contourpy takes them, z's rows along y
        self._mesh = (mesh_x, mesh_y)
        # Read-only views whether the sets were just solved or loaded from a
        # file: numba compiles a kernel once per argument type, and a flag
        # that differed between processes would compile it once more.
        self._values = {name: _read_only(s.value) for name, s in solution.sets.items()}
        self._times = {name: _read_only(s.time_to_win) for name, s in solution.sets.items()}

    def warm_up(self) -> None:
        """Run every compiled kernel of the queries once on each set, for
        the side effect: numba loads them from its cache, or compiles them
        into it, now rather than at the game's first fix (see
        ``CtfAdvisor.warm_up``)."""
        middle = self._lo + self._spacing * (np.asarray(self.geometry.grid.shape * 2) - 1) / 2
        interpolate_2d(self.geometry.blocked, self._lo[:2], self._spacing[:2], middle[:2])
        for name, value in self._values.items():
            _value_and_gradient(value, self._lo, self._spacing, middle)
            if self._times[name] is not None:
                _finite_gradient(self._times[name], self._lo, self._spacing, middle)
            _slice(value, self._lo[:2], self._spacing[:2], middle[:2], True)

    def value_set(self, phase: str) -> SetSolution:
        """The set that decides the rest of the game in ``phase``: W_A (or
        F_A) before the flag is taken, R_A after."""
        sets = self.solution.sets
        if phase == "return":
            if "return" not in sets:
                raise InputError("the flag-return phase needs R_A; solve the game with stages 'return' or 'both'")
            return sets["return"]
        if phase == "capture":
            for name in ("win", "capture"):
                if name in sets:
                    return sets[name]
            raise InputError("the flag-capture phase needs W_A or F_A; solve the game with stages 'both' or 'capture'")
        raise InputError(f"phase must be one of {', '.join(PHASES)}, got {phase!r}")

    def check_state(self, attacker, defender) -> np.ndarray:
        """The joint state as a float array, or an InputError naming the
        player that is off the grid or inside an obstacle."""
        return np.concatenate([self.check_point("attacker", attacker), self.check_point("defender", defender)])

    def check_point(self, who: str, point) -> np.ndarray:
        try:
            x, y = (float(v) for v in point)
        except (TypeError, ValueError):
            raise InputError(f"{who} position {point!r} is not a pair of numbers (x, y)") from None
        if not self.geometry.grid.contains((x, y)):
            (xmin, ymin), (xmax, ymax) = self.geometry.grid.lo, self.geometry.grid.hi
            raise InputError(
                f"{who} at ({x:.2f}, {y:.2f}) is off the game's grid [{xmin:g}, {xmax:g}] x [{ymin:g}, {ymax:g}]"
            )
        if self.blocked_at((x, y)):
            raise InputError(f"{who} at ({x:.2f}, {y:.2f}) is inside an obstacle or outside the area")
        return np.array([x, y])

    def blocked_at(self, point) -> bool:
        g = self.geometry.grid
        distance = interpolate_2d(
            self.geometry.blocked, np.asarray(g.lo), np.asarray(g.spacing), np.asarray(point, float)
        )
        return distance < -EDGE_SLACK * min(g.spacing)

    def evaluate(self, attacker, defender, phase: str = "capture") -> StateReport:
        """Value and optimal headings at the state."""
        return self._report(self.value_set(phase), attacker, defender)

    def evaluate_set(self, name: str, attacker, defender) -> StateReport:
        """Value and headings of one solved set (``"return"``, ``"capture"`` or ``"win"``)."""
        if name not in self.solution.sets:
            raise InputError(f"the game was solved without set {name!r}; it has {', '.join(self.solution.sets)}")
        return self._report(self.solution.sets[name], attacker, defender)

    def _report(self, found: SetSolution, attacker, defender) -> StateReport:
        """Headings by eqs. 3.12-3.13: down the value's gradient for the
        attacker, up it for the defender; inside the set, where the value
        may be flat, the same on the time-to-win T* (the attacker hurries,
        the defender delays), as the end of thesis 3.4 prescribes."""
        state = self.check_state(attacker, defender)
        value, gradient = _value_and_gradient(self._values[found.name], self._lo, self._spacing, state)
        if value <= 0 and found.time_to_win is not None:
            towards = _finite_gradient(self._times[found.name], self._lo, self._spacing, state)
            if np.any(towards != 0):
                gradient = towards
        return StateReport(float(value), _unit(-gradient[:2]), _unit(gradient[2:]))

    def defender_region_values(self, attacker, phase: str = "capture") -> np.ndarray:
        """The value over defender positions with the attacker held at
        ``attacker``: ``> 0`` is R_D(x_a) (or F_D, W_D by phase)."""
        point = self.check_point("attacker", attacker)
        return _slice(self._values[self.value_set(phase).name], self._lo[:2], self._spacing[:2], point, True)

    def attacker_region_values(self, defender, phase: str = "capture") -> np.ndarray:
        """The value over attacker positions with the defender held at
        ``defender``: ``<= 0`` is R_A(x_d) (or F_A, W_A by phase)."""
        point = self.check_point("defender", defender)
        return _slice(self._values[self.value_set(phase).name], self._lo[2:], self._spacing[2:], point, False)

    def defender_region(self, attacker, phase: str = "capture") -> np.ndarray:
        """R_D(x_a) as a mask over the grid of one player."""
        return self.defender_region_values(attacker, phase) > 0

    def attacker_region(self, defender, phase: str = "capture") -> np.ndarray:
        """R_A(x_d) as a mask over the grid of one player."""
        return self.attacker_region_values(defender, phase) <= 0

    def polygons(self, values: np.ndarray, side: str):
        """The region ``values <= 0`` (``side="attacker"``) or ``values > 0``
        (``"defender"``) of a slice as a shapely (Multi)Polygon in map
        metres, traced at the zero level with holes where it has them."""
        if side not in ("attacker", "defender"):
            raise InputError(f"side must be 'attacker' or 'defender', got {side!r}")
        generator = _filled_contours(*self._mesh, np.asarray(values, np.float64).T)
        finite = float(np.max(np.abs(values))) + 1.0
        lower, upper = (-finite, 0.0) if side == "attacker" else (0.0, finite)
        points, offsets = cast("FillReturn_OuterOffset", generator.filled(lower, upper))  # as fill_type says
        shapes = []
        for outline, cuts in zip(points, offsets):
            rings = [outline[a:b] for a, b in itertools.pairwise(cuts) if b - a >= 4]
            if rings:
                shapes.append(shapely.Polygon(rings[0], rings[1:]))
        # Nodes exactly at zero (on a region's edge, where a signed distance
        # vanishes) leave degenerate holes and pieces that touch along an
        # edge; repair them into a valid shape of the same area.
        region = shapely.make_valid(shapely.MultiPolygon(shapes)) if shapes else shapely.MultiPolygon()
        parts = shapely.get_parts(region)
        polygons = [
            p for part in parts for p in shapely.get_parts(part) if isinstance(p, shapely.Polygon) and p.area > 0
        ]
        return (
            shapely.MultiPolygon(shapely.get_parts(shapely.union_all(polygons))) if polygons else shapely.MultiPolygon()
        )


def compile_kernels(dtype=np.float32) -> None:
    """Load or compile the query kernels for sets held in ``dtype``, with no
    game solved: on a blank game of five nodes a side. A kernel is compiled
    per argument type, not per grid, and every game's sets reach the
    kernels as the blank one's do (read-only arrays of ``dtype``, positions
    in float64), so a process that runs this fills numba's cache for every
    ground station after it."""
    grid = Grid((0.0, 0.0), (1.0, 1.0), (5, 5))
    inside = -np.ones(grid.shape)
    geometry = CtfGeometry(grid, blocked=np.ones(grid.shape), flag=inside, home=inside, terrain=np.ones(grid.shape))
    blank = np.zeros(grid.shape * 2, dtype)
    sets = {"return": SetSolution("return", blank, False, None, 0.0, 0, blank)}
    CtfQueries(CtfSolution(geometry, Rules(), sets)).warm_up()


def _filled_contours(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> contourpy.SerialContourGenerator:
    """The generator ``contourpy.contour_generator(x, y, z, fill_type="OuterOffset")``
    makes, from the nodes as 2-D arrays, without its checks and masked-array
    round trip: two thirds of the cost of a region's outline, which guidance
    traces several times a second. Non-finite values are masked as it masks them."""
    finite = np.isfinite(z)
    mask: Any = None if finite.all() else ~finite  # contourpy takes None for no mask, as its own call passes
    return contourpy.SerialContourGenerator(
        x,
        y,
        z,
        mask,
        corner_mask=True,
        line_type=contourpy.LineType.Separate,
        fill_type=contourpy.FillType.OuterOffset,
        quad_as_tri=False,
        z_interp=contourpy.ZInterp.Linear,
    )


def _read_only(a: np.ndarray | None) -> np.ndarray | None:
    if a is None:
        return None
    view = a.view()
    view.flags.writeable = False
    return view


def _unit(v: np.ndarray) -> tuple[float, float] | None:
    norm = math.hypot(float(v[0]), float(v[1]))
    if norm < 1e-9:
        return None
    return float(v[0]) / norm, float(v[1]) / norm


@numba.njit(cache=True)
def interpolate_2d(a, lo, spacing, point):
    """Bilinear value of the 2-D nodal array ``a`` at ``point``, clamped to the grid."""
    n0, n1 = a.shape
    f0 = min(max((point[0] - lo[0]) / spacing[0], 0.0), n0 - 1.0)
    f1 = min(max((point[1] - lo[1]) / spacing[1], 0.0), n1 - 1.0)
    i0, i1 = min(int(f0), n0 - 2), min(int(f1), n1 - 2)
    t0, t1 = f0 - i0, f1 - i1
    return (1 - t0) * ((1 - t1) * a[i0, i1] + t1 * a[i0, i1 + 1]) + t0 * (
        (1 - t1) * a[i0 + 1, i1] + t1 * a[i0 + 1, i1 + 1]
    )


@numba.njit(cache=True)
def _cell(n, lo, spacing, state):
    """The cell holding ``state`` (its lowest node) and the position within it, clamped to the grid."""
    base = np.empty(4, np.int64)
    frac = np.empty(4)
    for k in range(4):
        f = min(max((state[k] - lo[k]) / spacing[k], 0.0), n[k] - 1.0)
        base[k] = min(int(f), n[k] - 2)
        frac[k] = f - base[k]
    return base, frac


@numba.njit(cache=True)
def _corner(corner, base, frac, idx):
    """Set ``idx`` to corner number ``corner`` (one bit per axis) of the cell; its multilinear weight."""
    w = 1.0
    for k in range(4):
        bit = (corner >> k) & 1
        idx[k] = base[k] + bit
        w *= frac[k] if bit else 1.0 - frac[k]
    return w


@numba.njit(cache=True)
def _node_derivative(v, idx, axis, spacing, n):
    """Central difference of ``v`` along ``axis`` at node ``idx``, one-sided on the edges."""
    lo_idx = idx.copy()
    hi_idx = idx.copy()
    if idx[axis] > 0:
        lo_idx[axis] -= 1
    if idx[axis] < n[axis] - 1:
        hi_idx[axis] += 1
    span = (hi_idx[axis] - lo_idx[axis]) * spacing[axis]
    return (v[hi_idx[0], hi_idx[1], hi_idx[2], hi_idx[3]] - v[lo_idx[0], lo_idx[1], lo_idx[2], lo_idx[3]]) / span


@numba.njit(cache=True)
def _value_and_gradient(v, lo, spacing, state):
    n = np.array(v.shape)
    base, frac = _cell(n, lo, spacing, state)
    value = 0.0
    gradient = np.zeros(4)
    idx = np.empty(4, np.int64)
    for corner in range(16):
        w = _corner(corner, base, frac, idx)
        if w == 0.0:
            continue
        value += w * v[idx[0], idx[1], idx[2], idx[3]]
        for k in range(4):
            gradient[k] += w * _node_derivative(v, idx, k, spacing, n)
    return value, gradient


@numba.njit(cache=True)
def _finite_derivative(v, idx, axis, spacing, n):
    """Like ``_node_derivative`` but only through finite neighbours: T* is
    infinite outside the set, so at its edge the difference is one-sided."""
    centre = v[idx[0], idx[1], idx[2], idx[3]]
    if not np.isfinite(centre):
        return np.nan
    lo_idx = idx.copy()
    hi_idx = idx.copy()
    lo_idx[axis] = max(idx[axis] - 1, 0)
    hi_idx[axis] = min(idx[axis] + 1, n[axis] - 1)
    below = v[lo_idx[0], lo_idx[1], lo_idx[2], lo_idx[3]]
    above = v[hi_idx[0], hi_idx[1], hi_idx[2], hi_idx[3]]
    if not np.isfinite(below) or lo_idx[axis] == idx[axis]:
        below, lo_idx[axis] = centre, idx[axis]
    if not np.isfinite(above) or hi_idx[axis] == idx[axis]:
        above, hi_idx[axis] = centre, idx[axis]
    span = hi_idx[axis] - lo_idx[axis]
    return (above - below) / (span * spacing[axis]) if span > 0 else 0.0


@numba.njit(cache=True)
def _finite_gradient(v, lo, spacing, state):
    """The gradient of ``v`` at ``state`` interpolated from the finite
    corners of its cell only (weights renormalised); zero if none is."""
    n = np.array(v.shape)
    base, frac = _cell(n, lo, spacing, state)
    gradient = np.zeros(4)
    total = 0.0
    idx = np.empty(4, np.int64)
    d = np.empty(4)
    for corner in range(16):
        w = _corner(corner, base, frac, idx)
        if w == 0.0:
            continue
        finite = True
        for k in range(4):
            d[k] = _finite_derivative(v, idx, k, spacing, n)
            if not np.isfinite(d[k]):
                finite = False
        if finite:
            total += w
            for k in range(4):
                gradient[k] += w * d[k]
    if total > 0.0:
        gradient /= total
    return gradient


@numba.njit(cache=True)
def _slice(v, lo, spacing, point, held_first):
    """The 2-D slice of ``v`` with the first (``held_first``) or last two
    axes held at ``point``, bilinear in the held axes."""
    n = v.shape
    h0, h1 = (0, 1) if held_first else (2, 3)
    f0 = min(max((point[0] - lo[0]) / spacing[0], 0.0), n[h0] - 1.0)
    f1 = min(max((point[1] - lo[1]) / spacing[1], 0.0), n[h1] - 1.0)
    i0, i1 = min(int(f0), n[h0] - 2), min(int(f1), n[h1] - 2)
    t0, t1 = f0 - i0, f1 - i1
    w00, w01, w10, w11 = (1 - t0) * (1 - t1), (1 - t0) * t1, t0 * (1 - t1), t0 * t1
    if held_first:
        out = np.empty((n[2], n[3]))
        for a in range(n[2]):
            for b in range(n[3]):
                out[a, b] = (
                    w00 * v[i0, i1, a, b]
                    + w01 * v[i0, i1 + 1, a, b]
                    + w10 * v[i0 + 1, i1, a, b]
                    + w11 * v[i0 + 1, i1 + 1, a, b]
                )
    else:
        out = np.empty((n[0], n[1]))
        for a in range(n[0]):
            for b in range(n[1]):
                out[a, b] = (
                    w00 * v[a, b, i0, i1]
                    + w01 * v[a, b, i0, i1 + 1]
                    + w10 * v[a, b, i0 + 1, i1]
                    + w11 * v[a, b, i0 + 1, i1 + 1]
                )
    return out
