"""Maneuvers designed with reach-avoid sets (thesis 6.1).

A maneuver is a sequence of modes. Each mode has its dynamics: a fixed
feedback law folded into ``f0``, or a controlled input in a box, and
bounded disturbances (eq. 6.4). Each mode also has a target set, where it
hands over to the next mode. Three kinds of set come out of the HJI solver
of ``solvers.levelset.hji``:

- the capture set ``RA_T(T_k)`` (6.1.2, attainability): the states from
  which the mode reaches its target within ``T`` whatever the disturbance
  does. It is the reach-avoid set with nothing to avoid, with the control
  minimising and the disturbance maximising;
- the avoid set ``A_T(K)`` (6.1.2, safety): the states from which some
  disturbance drives the system into ``K`` within ``T`` whatever the
  control does. It is the same operator with the roles reversed: the
  disturbance reaches for ``K`` and the control, if the mode has one,
  opposes it;
- the forward reach ``Reach_T(S)`` (eq. 6.6): the states the system can be
  in within ``T`` of starting in ``S``. It is the backward set of the
  time-reversed dynamics, with the disturbance choosing.

The sequencing conditions of 6.1.3 are containments: each mode's target,
or where it can drift to while it hands over, must lie inside the next
mode's capture set. ``contained`` says whether one set lies inside
another, and by how much it does not.

Values follow ``solvers.levelset.hji``: ``<= 0`` inside, and in the units of the
target's function. Give signed distances (``box``) and the margins come
out in state units.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bearcat.solvers.errors import InputError
from bearcat.solvers.grid import Grid
from bearcat.solvers.levelset.hamiltonians import Box, ControlAffine
from bearcat.solvers.levelset.hji import ReachAvoidResult, solve_reach_avoid

__all__ = [
    "Containment",
    "Mode",
    "Sequence",
    "avoid_set",
    "box",
    "capture_sequence",
    "capture_set",
    "contained",
    "forward_reach",
]


def box(grid: Grid, lo, hi) -> np.ndarray:
    """A signed distance to the box ``[lo, hi]`` in scaled state units: each
    axis is divided by its half-width, so the value is <= 0 exactly inside,
    and -1 at the centre (the boxes of 6.1.3 mix degrees and degrees per
    second)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if lo.shape != (grid.ndim,) or hi.shape != (grid.ndim,) or (hi <= lo).any():
        raise InputError(f"a box on a {grid.ndim}-D grid needs lo < hi, one each per axis; got {lo} and {hi}")
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    axes = grid.mesh()
    return np.max([np.abs(a - c) / h for a, c, h in zip(axes, centre, half)], axis=0) - 1.0


def capture_set(grid: Grid, dynamics: ControlAffine, target, horizon: float, **solver) -> ReachAvoidResult:
    """``RA_T(T)``: where ``dynamics`` reaches ``target`` (<= 0 inside) within ``horizon`` against every disturbance."""
    return solve_reach_avoid(grid, dynamics, target, horizon=horizon, **solver)


def avoid_set(grid: Grid, dynamics: ControlAffine, unsafe, horizon: float, **solver) -> ReachAvoidResult:
    """``A_T(K)``: where some disturbance of ``dynamics`` drives the state into
    ``unsafe`` (<= 0 inside) within ``horizon``, whatever the control does."""
    swapped = ControlAffine(
        _swapped(dynamics.dynamics),
        control=_required(dynamics.disturbance, "an avoid set needs a disturbance to reach for the unsafe set"),
        disturbance=dynamics.control,
    )
    return solve_reach_avoid(grid, swapped, unsafe, horizon=horizon, **solver)


def forward_reach(grid: Grid, dynamics: ControlAffine, start, horizon: float, **solver) -> ReachAvoidResult:
    """``Reach_T(S)``: every state ``dynamics`` can be in within ``horizon`` of
    starting in ``start`` (<= 0 inside), for some disturbance; a controlled
    input, if there is one, may do anything within its bounds too."""
    inputs = [s for s in (dynamics.control, dynamics.disturbance) if s is not None]
    boxes = [s for s in inputs if isinstance(s, Box)]
    if not inputs or len(boxes) < len(inputs):
        raise InputError("a forward reach needs the mode's inputs as boxes (at least one)")
    lo = tuple(v for s in boxes for v in s.lo)
    hi = tuple(v for s in boxes for v in s.hi)
    reversed_dynamics = ControlAffine(_reversed(dynamics.dynamics, dynamics.control, dynamics.disturbance), Box(lo, hi))
    return solve_reach_avoid(grid, reversed_dynamics, start, horizon=horizon, **solver)


@dataclass(frozen=True)
class Containment:
    """Whether set ``inner`` lies inside set ``outer``. ``outside`` is the
    share of ``inner``'s nodes that lie outside ``outer``. ``worst`` is the
    largest value of ``outer`` on ``inner``, which is how far outside it
    reaches, in the units of ``outer``'s value (<= 0 when it holds)."""

    inner: str
    outer: str
    holds: bool
    outside: float
    worst: float

    def __str__(self) -> str:
        if self.holds:
            return f"{self.inner} lies inside {self.outer} (margin {-self.worst:.3g})"
        return (
            f"{self.inner} is not inside {self.outer}: {100 * self.outside:.1f} % of it lies outside, "
            f"up to {self.worst:.3g} beyond its edge"
        )


def contained(inner: np.ndarray, outer: np.ndarray, names: tuple[str, str]) -> Containment:
    """Whether ``{inner <= 0}`` lies inside ``{outer <= 0}`` on the same grid."""
    inner, outer = np.asarray(inner), np.asarray(outer)
    if inner.shape != outer.shape:
        raise InputError(f"{names[0]} and {names[1]} are on different grids: {inner.shape} and {outer.shape}")
    members = inner <= 0
    if not members.any():
        raise InputError(f"{names[0]} is empty on this grid: nothing to contain")
    values = outer[members]
    worst = float(values.max())
    return Containment(names[0], names[1], worst <= 0.0, float((values > 0).mean()), worst)


@dataclass(frozen=True)
class Mode:
    """One mode of a maneuver: its closed loop (a fixed law folded into
    ``f0``, or a control box) with its disturbance, its target (<= 0 inside,
    on the maneuver's grid, named as the thesis names it, e.g. ``T2``) and
    the time its capture set allows."""

    name: str
    dynamics: ControlAffine
    target: np.ndarray
    target_name: str
    horizon: float


@dataclass(frozen=True)
class Sequence:
    """The capture set of each mode by name, and the sequencing conditions
    in flight order (the first is the maneuver's start)."""

    capture: dict[str, ReachAvoidResult]
    checks: list[Containment]

    @property
    def holds(self) -> bool:
        return all(check.holds for check in self.checks)

    def failures(self) -> list[Containment]:
        return [check for check in self.checks if not check.holds]


def capture_sequence(
    grid: Grid,
    modes: list[Mode],
    *,
    start: tuple[str, np.ndarray],
    handovers: dict[str, tuple[str, np.ndarray]] | None = None,
    progress: Callable[[str, float, float, float], None] | None = None,
    **solver,
) -> Sequence:
    """Each mode's ``RA_T(T_k)``, solved from the last mode backwards
    (6.1.3), and the conditions that chain them: the ``start`` set lies in
    the first mode's capture set, and what each mode hands over lies in the
    next one's. A mode hands over its target, unless ``handovers`` names
    another set for it (the forward reach of a transition such as the
    motors' turn-off, eq. 6.6). ``progress(set name, t, horizon, change)``
    follows each solve."""
    handovers = handovers or {}
    capture: dict[str, ReachAvoidResult] = {}
    for mode in reversed(modes):
        name = f"RA_T({mode.target_name})"
        tick = None if progress is None else (lambda t, change, n=name, h=mode.horizon: progress(n, t, h, change))
        capture[mode.name] = capture_set(grid, mode.dynamics, mode.target, mode.horizon, progress=tick, **solver)
    first = modes[0]
    checks = [contained(start[1], capture[first.name].value, (start[0], _capture_name(first)))]
    for mode, following in itertools.pairwise(modes):
        label, handed = handovers.get(mode.name, (f"{mode.target_name} (the {mode.name}'s target)", mode.target))
        checks.append(contained(handed, capture[following.name].value, (label, _capture_name(following))))
    return Sequence(capture, checks)


def _capture_name(mode: Mode) -> str:
    return f"RA_T({mode.target_name}) (the {mode.name}'s capture set)"


def _required(s, why: str):
    if s is None:
        raise InputError(why)
    return s


def _swapped(dynamics: Callable) -> Callable:
    """``dynamics`` with its control and disturbance matrices exchanged."""
    import numba

    inner = numba.njit(dynamics) if not hasattr(dynamics, "py_func") else dynamics

    @numba.njit
    def swapped(x, f0, G, K):  # pragma: no cover - compiled
        inner(x, f0, K, G)

    return swapped


def _reversed(dynamics: Callable, control, disturbance) -> Callable:
    """``-f``, with the control and disturbance as one input (``[u, d]``), for the forward reach."""
    import numba

    inner = numba.njit(dynamics) if not hasattr(dynamics, "py_func") else dynamics
    m = 0 if control is None else len(control.lo)
    q = 0 if disturbance is None else len(disturbance.lo)

    @numba.njit
    def reversed_dynamics(x, f0, G, K):  # pragma: no cover - compiled
        n = x.shape[0]
        g = np.zeros((n, m))
        k = np.zeros((n, q))
        inner(x, f0, g, k)
        for i in range(n):
            f0[i] = -f0[i]
            for j in range(m):
                G[i, j] = -g[i, j]
            for j in range(q):
                G[i, m + j] = -k[i, j]

    return reversed_dynamics
