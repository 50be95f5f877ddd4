"""Capture-the-flag answers that hold wherever the players may really be.

A fix is stale and noisy: the player is somewhere in a disk around it, of
radius top speed x the fix's age plus its 95 % error radius, and not inside
an obstacle (nor, for the defender, in a region it may not enter). The plain
queries (``ctf.queries``) answer for the fixes as if they were exact; the
breakdowns of thesis 3.5.2 (the false go, the defender faked out by a stale
position) come from that. This module answers for the sets instead:

- the attacker's worst case is the largest value over both sets, so its go
  (worst case <= 0) holds against every defender position from every
  attacker position the fixes allow;
- the defender's worst case is the smallest, so it is shown "winning" only
  if it wins against all of them;
- each player's heading is the one whose step leaves its worst case best,
  over the opponent's set, from the player's own fix; an attacker that wins
  against the whole set hurries instead, as the plain heading does: the
  step that leaves its worst time to win (T*) least.

How the extreme is found, exactly rather than by sampling: the value is
multilinear in each 4-D cell, and a multilinear function's extremes over an
axis-aligned box lie at the box's corners. Each player's set is covered by
boxes, one per grid cell the disk meets, the bounding box of the part of
the disk inside that cell (a cell cut by the edge of where the player may be
is split 4 x 4 first, and the pieces wholly outside it dropped). The extreme over
the product of the two covers, which holds the product of the two sets, is
the extreme over pairs of box corners. It is exact where the disk covers
whole cells and errs only towards caution along the disk's rim, so it never
misses a state in the sets; a set of one point gives that point's value,
and the answers reduce to the plain ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from bearcat.solvers.ctf.queries import CtfQueries, StateReport, interpolate_2d
from bearcat.solvers.ctf.sets import EDGE_SLACK
from bearcat.solvers.errors import InputError

__all__ = ["Cover", "RobustCtf", "SideAnswer"]

SPLIT = 4
"""Sub-boxes per axis of a cell cut by the edge of where a player may be."""

DIRECTIONS = 32
"""Headings tried, besides the plain one and the one against the worst case."""


@dataclass(frozen=True)
class Cover:
    """The corners of the boxes covering one player's set, each as up to four
    weighted grid nodes (flat indices into the player's plane; unused slots
    have weight 0), around ``centre`` with ``radius``."""

    nodes: np.ndarray  # (m, 4) int64
    weights: np.ndarray  # (m, 4) float64
    centre: np.ndarray
    radius: float

    @property
    def size(self) -> int:
        return len(self.nodes)


@dataclass(frozen=True)
class SideAnswer:
    """What one player's display shows for uncertain positions: ``worst``
    is that player's worst case, the largest value over both sets for the
    attacker and the smallest for the defender; ``heading`` a unit (east,
    north) vector or None; ``plain`` the answer at the fixes themselves."""

    side: str
    worst: float
    heading: tuple[float, float] | None
    plain: StateReport

    @property
    def wins(self) -> bool:
        """The side wins from every state the sets allow: the attacker's go, the defender's "winning"."""
        return self.worst <= 0 if self.side == "attacker" else self.worst > 0

    @property
    def uncertain(self) -> bool:
        """The plain and the robust verdicts disagree."""
        return self.wins != ((self.plain.value <= 0) == (self.side == "attacker"))


class RobustCtf:
    """Worst-case answers on one solved game (see the module's docstring)."""

    def __init__(self, queries: CtfQueries) -> None:
        self.queries = queries
        geometry = queries.geometry
        grid = geometry.grid
        self._lo = np.asarray(grid.lo, np.float64)
        self._spacing = np.asarray(grid.spacing, np.float64)
        self._slack = EDGE_SLACK * min(grid.spacing)
        # Where each player may be: the free space; for the defender, less
        # the flag and return regions it forfeits by entering.
        self._allowed = {
            "attacker": geometry.blocked,
            "defender": np.minimum(np.minimum(geometry.flag, geometry.home), geometry.blocked),
        }
        self.step = 0.5 * min(grid.spacing)  # metres a heading is tried over
        self._transposed: dict[str, tuple] = {}
        angles = 2 * np.pi * np.arange(DIRECTIONS) / DIRECTIONS
        self._directions = np.stack([np.sin(angles), np.cos(angles)], axis=1)

    def cover(self, who: str, centre, radius: float) -> Cover:
        """The cover of player ``who``'s set: the disk of ``radius`` metres
        round ``centre`` (a point the player may be at), where it may be."""
        point = self.queries.check_point(who, centre)
        if not (radius >= 0 and math.isfinite(radius)):
            raise InputError(f"{who} uncertainty radius must be a finite number of metres >= 0, got {radius!r}")
        nodes, weights = _cover(self._allowed[who], self._lo, self._spacing, point, float(radius), self._slack)
        return Cover(nodes, weights, point, float(radius))

    def answer(self, side: str, attacker: Cover, defender: Cover, phase: str = "capture") -> SideAnswer:
        """``side``'s worst case and heading for the players' sets in ``phase``.

        The heading is tried against the opponent's worst place (the
        direction of steepest improvement of the worst case where one place
        is worst), the plain heading, and evenly spread ones, in that order;
        the first whose step leaves the worst case best wins, so the answer
        is never worse in the worst case than the plain heading. An attacker
        whose worst case is won scores the steps by its worst T* instead."""
        if side not in ("attacker", "defender"):
            raise InputError(f"side must be 'attacker' or 'defender', got {side!r}")
        flat = _flat(self.queries.value_set(phase).value)
        plain = self.queries.evaluate(attacker.centre, defender.centre, phase)
        sign = 1.0 if side == "attacker" else -1.0
        worst, a_k, d_k = _extreme(flat, attacker.nodes, attacker.weights, defender.nodes, defender.weights, sign)
        if attacker.size == 1 and defender.size == 1:
            return SideAnswer(side, worst, getattr(plain, f"{side}_heading"), plain)
        if side == "attacker":
            start, opponent = attacker.centre, defender
            worst_state = (attacker.centre, self._corner_point(defender, d_k))
        else:
            start, opponent = defender.centre, attacker
            worst_state = (self._corner_point(attacker, a_k), defender.centre)
        try:
            against = getattr(self.queries.evaluate(*worst_state, phase), f"{side}_heading")
        except InputError:  # the worst corner is that of a box an obstacle cuts, inside the obstacle
            against = None
        preferred = (against, getattr(plain, f"{side}_heading"))
        tried = np.array([h for h in preferred if h is not None] + [tuple(d) for d in self._directions])
        # Where the attacker wins against the whole set the value is flat
        # wherever every path reaches the target's deepest point, so, as the
        # plain heading does (end of thesis 3.4), it hurries: the step that
        # leaves its worst time to win, T* over the defender's set, least.
        found = self.queries.value_set(phase)
        time_to_win = found.time_to_win if side == "attacker" and worst <= 0 else None
        scored = [flat] if time_to_win is None else [_flat(time_to_win), flat]
        k = -1
        for matrix in scored:  # T* is infinite where a step leaves the set: then by the value
            k = _best_heading(
                matrix,
                self._allowed[side],
                self._lo,
                self._spacing,
                self._slack,
                start,
                self.step,
                tried,
                (opponent.nodes, opponent.weights),
                side == "attacker",
            )
            if k >= 0:
                break
        heading = None if k < 0 else (float(tried[k, 0]), float(tried[k, 1]))
        return SideAnswer(side, worst, heading, plain)

    def region_values(self, side: str, opponent: Cover, phase: str = "capture") -> np.ndarray:
        """Over the positions of ``side`` (a 2-D array on the player grid),
        the worst case against ``opponent``'s set, for the opponent's display:
        for the attacker's positions the smallest value over the defender's
        set (``<= 0``: the attacker may win from there, the robust R_A(x_d));
        for the defender's, the largest over the attacker's set (``> 0``: the
        defender may win from there, the robust R_D(x_a))."""
        shape = self.queries.geometry.grid.shape
        if side == "defender":
            flat = _flat(self.queries.value_set(phase).value)
            return _rows_combined_extreme(flat, opponent.nodes, opponent.weights, 1.0).reshape(shape)
        if side == "attacker":
            return _rows_combined_extreme(self._by_defender(phase), opponent.nodes, opponent.weights, -1.0).reshape(
                shape
            )
        raise InputError(f"side must be 'attacker' or 'defender', got {side!r}")

    def _by_defender(self, phase: str) -> np.ndarray:
        """The value as a matrix of defender nodes by attacker nodes, copied
        once per set, so a defender's display reads contiguous rows."""
        found = self.queries.value_set(phase)
        if self._transposed.get(phase, (None,))[0] is not found:
            self._transposed[phase] = (found, np.ascontiguousarray(_flat(found.value).T))
        return self._transposed[phase][1]

    def _corner_point(self, cover: Cover, k: int) -> np.ndarray:
        """Corner ``k`` of a cover back in metres (from its node weights)."""
        i, j = np.unravel_index(cover.nodes[k], self.queries.geometry.grid.shape)
        w = cover.weights[k]
        return self._lo + self._spacing * np.array([float(w @ i), float(w @ j)])


def _flat(value: np.ndarray) -> np.ndarray:
    """The 4-D value as a matrix, attacker nodes by defender nodes (a view)."""
    n = value.shape
    return value.reshape(n[0] * n[1], n[2] * n[3])


# ---------------------------------------------------------------- kernels


@numba.njit(cache=True)
def _all_outside(allowed, lo, spacing, slack, x0, x1, y0, y1, at):
    """Whether the box's four corners are all outside the allowed space, and
    so (the field being bilinear in a cell) all of the box."""
    for x in (x0, x1):
        for y in (y0, y1):
            at[0], at[1] = x, y
            if interpolate_2d(allowed, lo, spacing, at) >= -slack:
                return False
    return True


@numba.njit(cache=True)
def _clip(x0, x1, y0, y1, cx, cy, r):
    """The bounding box of the disk (cx, cy, r) within the box [x0, x1] x [y0, y1]; empty if lo > hi."""
    dy = max(y0 - cy, 0.0, cy - y1)
    dx = max(x0 - cx, 0.0, cx - x1)
    if dx * dx + dy * dy > r * r:
        return 1.0, 0.0, 1.0, 0.0
    half_w = math.sqrt(max(r * r - dy * dy, 0.0))
    half_h = math.sqrt(max(r * r - dx * dx, 0.0))
    return max(x0, cx - half_w), min(x1, cx + half_w), max(y0, cy - half_h), min(y1, cy + half_h)


@numba.njit(cache=True)
def _weights_of(lo, spacing, n0, n1, x, y, nodes, weights, k):
    """Row ``k`` of ``nodes``/``weights``: the bilinear corners of (x, y), zero weights dropped to slot ends."""
    f0 = min(max((x - lo[0]) / spacing[0], 0.0), n0 - 1.0)
    f1 = min(max((y - lo[1]) / spacing[1], 0.0), n1 - 1.0)
    i0, i1 = min(int(f0), n0 - 2), min(int(f1), n1 - 2)
    t0, t1 = f0 - i0, f1 - i1
    slot = 0
    for u in range(2):
        for v in range(2):
            w = (t0 if u else 1.0 - t0) * (t1 if v else 1.0 - t1)
            if w > 1e-12:
                nodes[k, slot] = (i0 + u) * n1 + (i1 + v)
                weights[k, slot] = w
                slot += 1
    for s in range(slot, 4):
        nodes[k, s] = 0
        weights[k, s] = 0.0


@numba.njit(cache=True)
def _cover(allowed, lo, spacing, centre, r, slack):
    n0, n1 = allowed.shape
    cx, cy = centre[0], centre[1]
    hx, hy = spacing[0], spacing[1]
    if r == 0.0:
        nodes = np.zeros((1, 4), np.int64)
        weights = np.zeros((1, 4))
        _weights_of(lo, spacing, n0, n1, cx, cy, nodes, weights, 0)
        return nodes, weights
    ia = max(int(math.floor((cx - r - lo[0]) / hx)), 0)
    ib = min(int(math.floor((cx + r - lo[0]) / hx)), n0 - 2)
    ja = max(int(math.floor((cy - r - lo[1]) / hy)), 0)
    jb = min(int(math.floor((cy + r - lo[1]) / hy)), n1 - 2)
    # Corners on the lattice of sub-box corners are shared between boxes:
    # marked once here; corners a clip moved off it are listed.
    fine = np.zeros(((n0 - 1) * SPLIT + 1, (n1 - 1) * SPLIT + 1), np.bool_)
    at = np.empty(2)
    capacity = 64
    px = np.empty(capacity)
    py = np.empty(capacity)
    count = 0
    for i in range(ia, ib + 1):
        for j in range(ja, jb + 1):
            x0, y0 = lo[0] + i * hx, lo[1] + j * hy
            cut = (
                allowed[i, j] < -slack
                or allowed[i + 1, j] < -slack
                or allowed[i, j + 1] < -slack
                or allowed[i + 1, j + 1] < -slack
            )
            parts = SPLIT if cut else 1
            sx, sy = hx / parts, hy / parts
            for u in range(parts):
                for v in range(parts):
                    bx0, by0 = x0 + u * sx, y0 + v * sy
                    bx1, by1 = bx0 + sx, by0 + sy
                    if cut and _all_outside(allowed, lo, spacing, slack, bx0, bx1, by0, by1, at):
                        continue  # wholly inside: a bilinear function's extremes are at corners
                    qx0, qx1, qy0, qy1 = _clip(bx0, bx1, by0, by1, cx, cy, r)
                    if qx0 > qx1 or qy0 > qy1:
                        continue
                    for a in range(2):
                        for b in range(2):
                            x = qx1 if a else qx0
                            y = qy1 if b else qy0
                            fx = (x - lo[0]) / hx * SPLIT
                            fy = (y - lo[1]) / hy * SPLIT
                            rx, ry = round(fx), round(fy)
                            if abs(fx - rx) < 1e-7 and abs(fy - ry) < 1e-7:
                                fine[int(rx), int(ry)] = True
                                continue
                            if count == capacity:
                                capacity *= 2
                                grown_x = np.empty(capacity)
                                grown_y = np.empty(capacity)
                                grown_x[:count] = px[:count]
                                grown_y[:count] = py[:count]
                                px, py = grown_x, grown_y
                            px[count] = x
                            py[count] = y
                            count += 1
    total = count + int(fine.sum())
    nodes = np.zeros((max(total, 1), 4), np.int64)
    weights = np.zeros((max(total, 1), 4))
    k = 0
    for fi in range(ia * SPLIT, (ib + 1) * SPLIT + 1):
        for fj in range(ja * SPLIT, (jb + 1) * SPLIT + 1):
            if fine[fi, fj]:
                if fi % SPLIT == 0 and fj % SPLIT == 0:
                    nodes[k, 0] = (fi // SPLIT) * n1 + fj // SPLIT
                    weights[k, 0] = 1.0
                else:
                    x = lo[0] + fi * hx / SPLIT
                    y = lo[1] + fj * hy / SPLIT
                    _weights_of(lo, spacing, n0, n1, x, y, nodes, weights, k)
                k += 1
    for c in range(count):
        _weights_of(lo, spacing, n0, n1, px[c], py[c], nodes, weights, k)
        k += 1
    if total == 0:  # the centre itself is allowed, so only a radius below rounding leaves nothing
        _weights_of(lo, spacing, n0, n1, cx, cy, nodes, weights, 0)
    return nodes, weights


@numba.njit(cache=True)
def _best_heading(flat, allowed, lo, spacing, slack, start, step, headings, opponent, attacker):
    """The index of the heading in ``headings`` (the first of equals) whose
    step from ``start`` leaves the mover's worst case of ``flat`` (the value,
    or T*) over the opponent's corners (``opponent``: nodes, weights) best,
    and finite; -1 if no step stays on the grid, in the allowed space and
    finite."""
    n0, n1 = allowed.shape
    nodes, weights = opponent
    here_nodes = np.zeros((1, 4), np.int64)
    here_weights = np.zeros((1, 4))
    sign = 1.0 if attacker else -1.0
    at = np.empty(2)
    best, best_score = -1, np.inf
    for k in range(headings.shape[0]):
        x = start[0] + step * headings[k, 0]
        y = start[1] + step * headings[k, 1]
        if not (lo[0] <= x <= lo[0] + (n0 - 1) * spacing[0] and lo[1] <= y <= lo[1] + (n1 - 1) * spacing[1]):
            continue
        at[0], at[1] = x, y
        if interpolate_2d(allowed, lo, spacing, at) < -slack:
            continue
        _weights_of(lo, spacing, n0, n1, x, y, here_nodes, here_weights, 0)
        score = -np.inf
        for q in range(nodes.shape[0]):
            v = 0.0
            for s in range(4):
                w_here = here_weights[0, s]
                if w_here == 0.0:
                    break
                for t in range(4):
                    w_there = weights[q, t]
                    if w_there == 0.0:
                        break
                    if attacker:
                        v += w_here * w_there * flat[here_nodes[0, s], nodes[q, t]]
                    else:
                        v += w_here * w_there * flat[nodes[q, t], here_nodes[0, s]]
            score = max(score, sign * v)
        if score < best_score - 1e-9 and score < np.inf:
            best, best_score = k, score
    return best


@numba.njit(cache=True)
def _extreme(flat, a_nodes, a_weights, d_nodes, d_weights, sign):
    """The largest (``sign`` 1) or smallest (-1) value over every pair of an
    attacker corner and a defender corner; and the pair's indices."""
    best = -np.inf
    best_a, best_d = 0, 0
    for p in range(a_nodes.shape[0]):
        for q in range(d_nodes.shape[0]):
            v = 0.0
            for s in range(4):
                wa = a_weights[p, s]
                if wa == 0.0:
                    break
                row = a_nodes[p, s]
                inner = 0.0
                for t in range(4):
                    wd = d_weights[q, t]
                    if wd == 0.0:
                        break
                    inner += wd * flat[row, d_nodes[q, t]]
                v += wa * inner
            if sign * v > best:
                best, best_a, best_d = sign * v, p, q
    return sign * best, best_a, best_d


@numba.njit(cache=True)
def _rows_combined_extreme(matrix, nodes, weights, sign):
    """For every column of ``matrix``, the extreme over the corners (weighted
    rows) of a cover."""
    m = matrix.shape[1]
    out = np.full(m, -np.inf)
    row = np.empty(m)
    for p in range(nodes.shape[0]):
        row[:] = 0.0
        for s in range(4):
            w = weights[p, s]
            if w == 0.0:
                break
            row += w * matrix[nodes[p, s]]
        for k in range(m):
            if sign * row[k] > out[k]:
                out[k] = sign * row[k]
    return sign * out
