"""Capture-the-flag answers over a belief: the value at many joint states at
once, a quantile of it, and the heading whose step leaves that quantile best.

Where ``ctf.robust`` answers for the worst of a disk round each fix, this
module answers for samples of where the players are believed to be (a
tracker's mixture, ``agents.ground_station.tracker``): the defender acts on
a low quantile of the value over them, the share of the belief it accepts
to lose against, rather than on the minimum over a disk, which the holding
study found lost for every heading once the disk is wider than the margin.

Each sample is a joint state: attacker sample ``i`` with defender sample
``i``. A heading is scored by stepping the mover's samples all by the same
vector (the player moves, the belief moves with it) and taking the
quantile of the value over the stepped states; the opponent stays where it
is believed to be, as in ``ctf.robust``'s heading search.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from bearcat.solvers.ctf.queries import CtfQueries, interpolate_2d
from bearcat.solvers.ctf.sets import EDGE_SLACK
from bearcat.solvers.errors import InputError

__all__ = ["SampledAnswer", "SampledCtf"]

DIRECTIONS = 32
"""Headings tried, besides the preferred ones, evenly round the circle."""


@dataclass(frozen=True)
class SampledAnswer:
    """``side``'s quantile of the value over the samples, where it stands
    (``value``), and its heading (a unit (east, north) vector, or None when no
    step stays on the grid and out of obstacles)."""

    side: str
    value: float
    heading: tuple[float, float] | None


class SampledCtf:
    """Quantile answers on one solved game (see the module's docstring)."""

    def __init__(self, queries: CtfQueries) -> None:
        self.queries = queries
        grid = queries.geometry.grid
        self._lo = np.asarray(grid.lo * 2, np.float64)
        self._spacing = np.asarray(grid.spacing * 2, np.float64)
        self.step = 0.5 * min(grid.spacing)  # metres a heading is tried over
        self._slack = EDGE_SLACK * min(grid.spacing)
        angles = 2 * np.pi * np.arange(DIRECTIONS) / DIRECTIONS
        self._directions = np.stack([np.sin(angles), np.cos(angles)], axis=1)

    def values(self, attackers, defenders, phase: str = "capture") -> np.ndarray:
        """The value at each joint state (``attackers[i]``, ``defenders[i]``),
        map metres, clamped to the grid as every query is."""
        a, d = _pairs(attackers, defenders)
        value = self.queries.value_set(phase).value
        return _values_at(value, self._lo, self._spacing, a, d, _NO_STEP, False)[0]

    def quantile(self, attackers, defenders, level: float, phase: str = "capture") -> float:
        """The ``level`` quantile of the value over the joint samples (numpy's "linear" rule)."""
        a, d = _pairs(attackers, defenders)
        value = self.queries.value_set(phase).value
        return float(_row_quantiles(_values_at(value, self._lo, self._spacing, a, d, _NO_STEP, False), level)[0])

    def answer(
        self, side: str, attackers, defenders, level: float, phase: str = "capture", preferred=()
    ) -> SampledAnswer:
        """``side``'s quantile at ``level`` of the value over the samples and
        its heading. The defender maximises the ``level`` quantile (it may
        lose against that share of the belief); the attacker minimises the
        ``1 - level`` quantile. Headings in ``preferred`` (unit vectors, or
        None) are tried first, then evenly spread ones; the first of equals
        wins, so a preferred heading is kept unless another is strictly better.
        A heading whose step from the belief's mean leaves the grid or enters
        an obstacle is not tried."""
        if side not in ("attacker", "defender"):
            raise InputError(f"side must be 'attacker' or 'defender', got {side!r}")
        if not 0.0 < level < 1.0:
            raise InputError(f"the quantile level must lie between 0 and 1, got {level!r}")
        a, d = _pairs(attackers, defenders)
        mover = a if side == "attacker" else d
        q = level if side == "defender" else 1.0 - level
        sign = -1.0 if side == "defender" else 1.0  # the mover minimises sign x quantile
        value = self.queries.value_set(phase).value
        here = float(_row_quantiles(_values_at(value, self._lo, self._spacing, a, d, _NO_STEP, False), q)[0])
        tried = np.array([h for h in preferred if h is not None] + [tuple(u) for u in self._directions], float)
        geometry = self.queries.geometry
        usable = _open_steps(
            geometry.blocked, self._lo[:2], self._spacing[:2], self._slack, mover.mean(axis=0), self.step * tried
        )
        if not usable.any():
            return SampledAnswer(side, here, None)
        steps = self.step * tried[usable]
        stepped = _values_at(value, self._lo, self._spacing, a, d, steps, side == "defender")
        scores = sign * _row_quantiles(stepped, q)
        best = int(np.argmin(scores))  # the first of equals
        heading = tried[usable][best]
        return SampledAnswer(side, here, (float(heading[0]), float(heading[1])))


_NO_STEP = np.zeros((1, 2))


def _pairs(attackers, defenders) -> tuple[np.ndarray, np.ndarray]:
    a = np.ascontiguousarray(attackers, dtype=np.float64).reshape(-1, 2)
    d = np.ascontiguousarray(defenders, dtype=np.float64).reshape(-1, 2)
    if len(a) != len(d) or len(a) == 0:
        raise InputError(f"samples come in joint pairs: {len(a)} attacker and {len(d)} defender positions")
    if not (np.isfinite(a).all() and np.isfinite(d).all()):
        raise InputError("every sampled position must be finite")
    return a, d


@numba.njit(cache=True)
def _values_at(v, lo, spacing, attackers, defenders, steps, defender_moves):
    """The multilinear value at every joint state with the mover's samples
    stepped by each row of ``steps``: an (h, n) array."""
    h, n = steps.shape[0], attackers.shape[0]
    shape = v.shape
    out = np.empty((h, n))
    state = np.empty(4)
    base = np.empty(4, np.int64)
    frac = np.empty(4)
    for k in range(h):
        for i in range(n):
            state[0], state[1] = attackers[i, 0], attackers[i, 1]
            state[2], state[3] = defenders[i, 0], defenders[i, 1]
            offset = 2 if defender_moves else 0
            state[offset] += steps[k, 0]
            state[offset + 1] += steps[k, 1]
            for axis in range(4):
                f = min(max((state[axis] - lo[axis]) / spacing[axis], 0.0), shape[axis] - 1.0)
                base[axis] = min(int(f), shape[axis] - 2)
                frac[axis] = f - base[axis]
            total = 0.0
            for corner in range(16):
                w = 1.0
                i0, i1, i2, i3 = base[0], base[1], base[2], base[3]
                if corner & 1:
                    i0 += 1
                    w *= frac[0]
                else:
                    w *= 1.0 - frac[0]
                if corner & 2:
                    i1 += 1
                    w *= frac[1]
                else:
                    w *= 1.0 - frac[1]
                if corner & 4:
                    i2 += 1
                    w *= frac[2]
                else:
                    w *= 1.0 - frac[2]
                if corner & 8:
                    i3 += 1
                    w *= frac[3]
                else:
                    w *= 1.0 - frac[3]
                if w != 0.0:
                    total += w * v[i0, i1, i2, i3]
            out[k, i] = total
    return out


@numba.njit(cache=True)
def _row_quantiles(values, q):
    """The ``q`` quantile of each row, interpolated linearly between order
    statistics as ``np.quantile`` does by default, without its per-call cost
    (a third of a millisecond, paid 33 times a second per phone)."""
    h, n = values.shape
    out = np.empty(h)
    at = q * (n - 1)
    below = min(int(np.floor(at)), n - 1)
    above = min(below + 1, n - 1)
    frac = at - below
    for k in range(h):
        row = np.sort(values[k])
        out[k] = row[below] + frac * (row[above] - row[below])
    return out


@numba.njit(cache=True)
def _open_steps(blocked, lo, spacing, slack, centre, steps):
    """Whether each step from ``centre`` ends on the grid and out of obstacles."""
    n0, n1 = blocked.shape
    out = np.empty(steps.shape[0], np.bool_)
    at = np.empty(2)
    for k in range(steps.shape[0]):
        at[0], at[1] = centre[0] + steps[k, 0], centre[1] + steps[k, 1]
        on = lo[0] <= at[0] <= lo[0] + (n0 - 1) * spacing[0] and lo[1] <= at[1] <= lo[1] + (n1 - 1) * spacing[1]
        out[k] = on and interpolate_2d(blocked, lo, spacing, at) >= -slack
    return out
