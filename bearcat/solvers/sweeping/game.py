"""The time to win of a two-player simple-motion reach-avoid game on a 4-D
grid, by fast sweeping of stationary equations instead of marching the
time-dependent one (``solvers.levelset.hji``).

The attacker, at ``(x0, x1)`` with speed map ``speed_a``, must reach the
target ``{l <= 0}`` without entering the avoid set ``{g <= 0}``; the
defender, at ``(x2, x3)`` with ``speed_d``, tries to stop it. Two
stationary problems give what the time marcher gives at convergence:

1. The reach-avoid value ``V``, the fixed point of the marcher's
   ``J <- max(min(J, l), -g)`` under the game's flow: the equation
   ``v_a |grad_a V| - v_d |grad_d V| = 0`` between ``l`` and ``-g``,
   swept down from ``max(l, -g)``. ``{V <= 0}`` is the set the attacker
   wins from, over any horizon. One solve of ``V`` is needed because the
   time to win alone jumps to infinity across the barriers where the
   defender's capture begins to hold, and an upwind scheme fed infinite
   neighbours spreads them a cell a sweep (Yang 2013 faces the same with
   its discontinuous value).
2. The time to win ``T*`` on ``{V <= 0}``: ``v_a |grad_a T| - v_d |grad_d
   T| = 1`` with ``T = 0`` on the target, swept down from a ceiling. Every
   finite-horizon set is ``{T* <= T}``.

Both use the Godunov upwinding of ``solvers.sweeping.kernels``, first
order. Pure numerics: arrays in, arrays out.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bearcat.solvers.errors import InputError
from bearcat.solvers.sweeping import kernels as kern

__all__ = ["SweepResult", "solve_time_to_win", "value_at"]

DEFAULT_TOL = 1e-3
"""Convergence tolerance in cells: a solve stops once a whole round of the
16 orderings moved no value by more than this many cells (of value, or of
time for the attacker to cross one)."""

MAX_ROUNDS = 40

Progress = Callable[[str, int, float], None]
"""``progress(stage, sweeps, change)`` after every sweep; stage ``value`` or ``time``."""


@dataclass(frozen=True, eq=False)
class SweepResult:
    """``value`` is ``V`` (metres of the target's function; ``<= 0`` where
    the attacker wins over any horizon) and ``time_to_win`` is ``T*`` (s; 0
    on the target, inf where the attacker cannot win). ``sweeps`` and
    ``node_updates`` count the work of the two solves; ``converged`` says
    whether both met the tolerance within ``MAX_ROUNDS`` rounds."""

    value: np.ndarray
    time_to_win: np.ndarray
    sweeps: tuple[int, int]
    node_updates: int
    converged: bool


def solve_time_to_win(
    spacing,
    speed_a: np.ndarray,
    speed_d: np.ndarray,
    target: np.ndarray,
    avoid: np.ndarray,
    *,
    ceiling: float,
    tol: float = DEFAULT_TOL,
    progress: Progress | None = None,
) -> SweepResult:
    """Solve ``V`` then ``T*`` (module docstring). ``spacing`` is the four
    axes' node spacings; ``target`` and ``avoid`` are ``l`` and ``g`` on the
    grid; ``ceiling`` (s) bounds the time to win the attacker could need
    from anywhere it wins (a few crossings of the map), the height ``T*``
    is swept down from."""
    target = np.ascontiguousarray(target, dtype=np.float64)
    avoid = np.ascontiguousarray(avoid, dtype=np.float64)
    speed_a = np.ascontiguousarray(speed_a, dtype=np.float64)
    speed_d = np.ascontiguousarray(speed_d, dtype=np.float64)
    shape = target.shape
    if len(shape) != 4 or avoid.shape != shape or speed_a.shape != shape[:2] or speed_d.shape != shape[2:]:
        raise InputError(
            f"a 4-D game needs target and avoid of one shape and speed maps of its attacker's and defender's "
            f"planes; got {shape}, {avoid.shape}, {speed_a.shape} and {speed_d.shape}"
        )
    inv_h = 1.0 / np.asarray(spacing, dtype=np.float64)
    cell = float(min(spacing))
    fastest = float(max(speed_a.max(), speed_d.max(), 1e-12))

    value = np.maximum(target, -avoid)
    no_kinds = np.zeros(1, np.uint8).reshape(1, 1, 1, 1)
    value_sweeps, value_updates, value_ok = _sweep_until_settled(
        "value", value, target, avoid, no_kinds, speed_a, speed_d, inv_h, kern.VALUE, tol * cell, progress
    )

    wins = value <= 0
    kind = np.where(wins, np.uint8(kern.UPDATE), np.uint8(kern.OUTSIDE))
    kind[wins & (target <= 0) & (avoid > 0)] = kern.FIXED
    time = np.where(kind == kern.UPDATE, ceiling, np.inf)
    time[kind == kern.FIXED] = 0.0
    time_sweeps, time_updates, time_ok = _sweep_until_settled(
        "time", time, target, avoid, kind, speed_a, speed_d, inv_h, kern.TIME, tol * cell / fastest, progress
    )
    return SweepResult(value, time, (value_sweeps, time_sweeps), value_updates + time_updates, value_ok and time_ok)


def _sweep_until_settled(stage, u, target, avoid, kind, speed_a, speed_d, inv_h, mode, tol, progress):
    """Sweep ``u`` in place, round after round of the 16 orderings, until a
    whole round changes nothing by more than ``tol``; (sweeps, node updates, converged)."""
    active = np.ones(u.shape, np.uint8)
    quiet = tol * 1e-3  # smaller changes wake no neighbour: they cannot move one by tol
    sweeps = updates = 0
    orders = kern.ORDERS
    for _ in range(MAX_ROUNDS):
        round_change = 0.0
        for order in orders:
            change, worked = kern.sweep(u, target, avoid, kind, speed_a, speed_d, inv_h, mode, order, active, quiet)
            sweeps += 1
            updates += int(worked)
            round_change = max(round_change, float(change))
            if progress is not None:
                progress(stage, sweeps, float(change))
        if round_change <= tol:
            return sweeps, updates, True
    return sweeps, updates, False


def value_at(result: SweepResult, horizon: float, speed: float) -> np.ndarray:
    """The reach-avoid value over ``horizon`` (s), the time marcher's ``J``
    after it: ``max(V, speed (T* - horizon))`` where the attacker wins at
    all, ``V`` elsewhere. Its zero sub-level set is ``{T* <= horizon}``; a
    state won only later than the horizon sits ``speed`` times its lateness
    above zero, in metres like ``V``."""
    if not (math.isfinite(horizon) and horizon > 0):
        raise InputError(f"the horizon must be a positive number of seconds, got {horizon}")
    late = np.where(np.isfinite(result.time_to_win), speed * (result.time_to_win - horizon), -np.inf)
    return np.maximum(result.value, late)
