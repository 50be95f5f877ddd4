"""The 1 vs 1 capture-the-flag game of thesis 3.1 and 3.3 as reach-avoid
problems on the joint state ``x = (x_a, y_a, x_d, y_d)``.

The attacker (control) must reach the flag ``F`` and then the return region
``R`` without coming within ``r_c`` of the defender (disturbance); the
defender forfeits by entering ``F``, ``R`` or a blocked place (an obstacle,
or the part of the grid's box outside the area), the attacker loses by
entering a blocked place. In the sets of 3.3.1:

    G_D = {x_d in F u R u blocked}       C_J = C u G_A,  G_A = {x_a blocked}
    R_A = RA_Tr({x_a in R} u G_D, C_J)                           (3.8)
    F_A = RA_Tc({x_a in F} u G_D, C_J)                           (3.9)
    W_A = RA_Tc(({x_a in F} n R_A) u G_D, C_J)

and the defender's sets are the complements. Every set is the sub-zero set
of a function built from signed distances of the 2-D geometry (``CtfGeometry``),
combined with ``min`` (union) and ``max`` (intersection); ``W_A`` takes the
value of ``R_A`` itself as the level set of the second stage's target.

The edges of the grid are the edges of the area: ``solvers.levelset.hji`` makes
leaving through them a loss for the attacker and a forfeit for the
defender without any avoid rows, so a return strip along an edge is reached
up to its last row. Only the part of the box outside a non-rectangular area
is "blocked", and a node exactly on an obstacle's edge is free, as in the
map model (free space is closed).

This module is pure numerics: arrays in, a ``CtfSolution`` out. Turning a
map into a ``CtfGeometry`` and caching solutions on disk live at the edges.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from bearcat.solvers.errors import InputError, non_negative, positive
from bearcat.solvers.grid import Grid
from bearcat.solvers.levelset.hamiltonians import Player, SimpleMotion
from bearcat.solvers.levelset.hji import (
    PaddedField,
    ReachAvoidResult,
    available_bytes,
    required_bytes,
    solve_reach_avoid,
)

__all__ = ["STAGES", "CtfGeometry", "CtfSolution", "Rules", "SetSolution", "required_game_bytes", "solve_ctf"]

STAGES = {
    "return": ("return",),  # R_A only: the flag-return game of the field trials (3.5)
    "capture": ("capture",),  # F_A only
    "both": ("return", "win"),  # R_A, then W_A from it: the two-stage game
    "all": ("return", "capture", "win"),  # and F_A, for an attacker that grabs the flag when W_A is lost
}
"""What each ``stages`` choice solves, in order."""

SET_NAMES = {"return": "R_A", "capture": "F_A", "win": "W_A"}

DEFAULT_TOL = 0.05
"""Convergence tolerance in cells, per two-cell window: the value is kept
from rising (``solvers.levelset.hji``, ``monotone``), so it settles rather than
ripples and the check finds the fixed point."""

# Nodes this close to a blocked place's edge (in cells) still count as free:
# the edge is walkable, and float32 rounding must not move it inside.
EDGE_SLACK = 1e-3


@dataclass(frozen=True, eq=False)
class CtfGeometry:
    """The game's 2-D geometry on the grid both players' positions live on.

    ``blocked``, ``flag`` and ``home`` are signed distances in metres
    (negative inside) to where nobody may be, to ``F`` and to ``R``;
    ``terrain`` is the speed factor in ``[0, 1]`` (0 where blocked), which
    scales both players' top speeds."""

    grid: Grid
    blocked: np.ndarray
    flag: np.ndarray
    home: np.ndarray
    terrain: np.ndarray

    def __post_init__(self) -> None:
        if self.grid.ndim != 2:
            raise InputError(f"the arena needs a 2-D grid, got {self.grid.ndim}-D")
        for name in ("blocked", "flag", "home", "terrain"):
            a = np.asarray(getattr(self, name), dtype=float)
            if a.shape != self.grid.shape:
                raise InputError(f"arena {name} has shape {a.shape} but the grid has {self.grid.shape}")
            if not np.isfinite(a).all():
                raise InputError(f"arena {name} has values that are not finite numbers")
            object.__setattr__(self, name, a)
        if (self.terrain < 0).any() or (self.terrain > 1).any():
            raise InputError("arena terrain speed factors must lie in [0, 1]")
        if not (self.flag <= 0).any():
            raise InputError("the flag region covers no node of the arena grid; refine the grid")
        if not (self.home <= 0).any():
            raise InputError("the return region covers no node of the arena grid; refine the grid")

    @property
    def free(self) -> np.ndarray:
        """Nodes either player may stand on."""
        return self.blocked > -EDGE_SLACK * min(self.grid.spacing)

    def joint_grid(self) -> Grid:
        """The 4-D grid of ``(x_a, y_a, x_d, y_d)``."""
        g = self.grid
        return Grid(g.lo * 2, g.spacing * 2, g.shape * 2)


@dataclass(frozen=True)
class Rules:
    """Top speeds (m/s on full-speed terrain), capture radius (m) and the
    time allowed for each stage (s): thesis 3.1.1."""

    attacker_speed: float = 1.0
    defender_speed: float = 1.0
    capture_radius: float = 0.5
    capture_time: float = 12.0
    return_time: float = 12.0

    def __post_init__(self) -> None:
        for name in ("attacker_speed", "defender_speed", "capture_time", "return_time"):
            object.__setattr__(self, name, positive(getattr(self, name), name.replace("_", " ")))
        object.__setattr__(self, "capture_radius", non_negative(self.capture_radius, "capture radius"))


@dataclass(frozen=True, eq=False)
class SetSolution:
    """One winning set: ``value <= 0`` is the attacker's, ``value > 0`` the
    defender's; plus how its solve went.

    ``time_to_win`` (T*, thesis end of 3.4) is the horizon at which each
    state joined the set: the time the attacker needs to win from it under
    optimal play (0 where it has already won, inf outside the set). Inside
    the set the value is flat wherever every strategy reaches the target's
    deepest point, so headings there come from the gradient of T*, whose
    level sets are the fronts the value's zero level passed through."""

    name: str
    value: np.ndarray
    converged: bool
    converged_at: float | None
    time: float
    steps: int
    time_to_win: np.ndarray | None = None
    node_updates: int | None = None  # None when loaded rather than solved
    device: str | None = None  # what solved it (solvers.levelset.devices.Device); None when loaded

    @property
    def attacker_wins(self) -> np.ndarray:
        return self.value <= 0

    @classmethod
    def from_result(cls, name: str, result: ReachAvoidResult) -> SetSolution:
        return cls(
            name,
            result.value,
            result.converged,
            result.converged_at,
            result.time,
            result.steps,
            result.tstar,
            result.node_updates,
            result.device,
        )


@dataclass(frozen=True, eq=False)
class CtfSolution:
    """The solved sets of one game, keyed ``"return"`` (R_A), ``"capture"``
    (F_A) and ``"win"`` (W_A), whichever were asked for."""

    geometry: CtfGeometry
    rules: Rules
    sets: dict[str, SetSolution] = field(default_factory=dict)

    @property
    def grid(self) -> Grid:
        return self.geometry.joint_grid()

    def first_stage(self) -> SetSolution:
        """The set that decides the game from its start: W_A if solved, else
        F_A, else R_A."""
        for name in ("win", "capture", "return"):
            if name in self.sets:
                return self.sets[name]
        raise InputError("the solution holds no set")


ProgressCallback = Callable[[str, float, float, float], None]
"""``progress(set_name, t, horizon, change)`` after every convergence check."""


def required_game_bytes(geometry: CtfGeometry, stages: str = "both", *, scheme: str = "weno5", dtype=np.float32) -> int:
    """Peak bytes of ``solve_ctf``: the solver's own arrays (with T*, and
    the target and avoid, built in place) plus the values and T* of the sets
    already solved."""
    grid = geometry.joint_grid()
    itemsize = np.dtype(dtype).itemsize
    kept = len(_stage_list(stages)) - 1
    solver = required_bytes(grid, scheme=scheme, dtype=dtype, record_tstar=True, record_gradient=False)
    return solver + 2 * kept * grid.size * itemsize


def solve_ctf(
    geometry: CtfGeometry,
    rules: Rules,
    stages: str = "both",
    *,
    scheme: str = "weno5",
    dtype=np.float32,
    tol: float = DEFAULT_TOL,
    known: dict[str, SetSolution] | None = None,
    progress: ProgressCallback | None = None,
    memory_limit: int | None = None,
    local: bool = False,
    device: str = "auto",
) -> CtfSolution:
    """Solve the sets of ``stages`` (see ``STAGES``). A set counts as
    converged (thesis 3.3.2) once its value changes by less than ``tol``
    cells while the faster player crosses two cells; ``known`` supplies
    sets already solved (e.g. R_A from a cache), keyed like
    ``CtfSolution.sets``. ``local`` solves each set by the narrow band
    (``solvers.levelset.hji.solve_reach_avoid``): the same sets and T*, with the
    defender's margins clamped a few cells out (``CtfQueries`` says what
    that leaves of the guidance). ``device`` is where the sets are solved
    (``"auto"``, ``"cpu"`` or ``"cuda"``, as ``solve_reach_avoid`` takes it);
    the sets are the same on each."""
    names = _stage_list(stages)
    known = dict(known or {})
    grid = geometry.joint_grid()
    limit = available_bytes() if memory_limit is None else int(memory_limit)
    need = required_game_bytes(geometry, stages, scheme=scheme, dtype=dtype)
    if need > limit and not set(names) <= set(known):
        raise InputError(
            f"a {'x'.join(map(str, grid.shape))} game ({grid.size:,} joint states) needs about "
            f"{need / 1e9:.2f} GB for the {scheme} solve but only {limit / 1e9:.2f} GB of memory is available; "
            "use a coarser grid"
        )
    dtype = np.dtype(dtype)
    game = _pursuit(geometry, rules)
    forfeit = _defender_forfeits(geometry)
    avoid = None  # built once, and only if a set is left to solve
    sets: dict[str, SetSolution] = {}
    for name in names:
        if name in known:
            sets[name] = known[name]
            continue
        if avoid is None:
            avoid = _avoid(geometry, rules, dtype)
        horizon = rules.return_time if name == "return" else rules.capture_time
        target = _target(name, geometry, forfeit, sets, dtype)
        report = None if progress is None else (lambda t, change, n=name, h=horizon: progress(n, t, h, change))
        result = solve_reach_avoid(
            grid,
            game,
            target,
            avoid,
            horizon=horizon,
            scheme=scheme,
            dtype=dtype,
            tol=tol * min(geometry.grid.spacing),
            check_every=_check_window(geometry, rules),
            record_tstar=True,
            record_gradient=False,
            progress=report,
            memory_limit=limit,
            local=local,
            device=device,
        )
        del target
        sets[name] = SetSolution.from_result(name, result)
    return CtfSolution(geometry, rules, sets)


def _stage_list(stages: str) -> tuple[str, ...]:
    try:
        return STAGES[stages]
    except (KeyError, TypeError):
        raise InputError(f"stages must be one of {', '.join(STAGES)}, got {stages!r}") from None


def _check_window(geometry: CtfGeometry, rules: Rules) -> float:
    """Seconds the faster player needs to cross two cells, the window of the
    convergence check: in cells and cell-crossing times the check means the
    same on a 10 m and a 400 m map."""
    return 2.0 * max(geometry.grid.spacing) / max(rules.attacker_speed, rules.defender_speed)


def _pursuit(geometry: CtfGeometry, rules: Rules) -> SimpleMotion:
    terrain = geometry.terrain
    return SimpleMotion(
        (
            Player((0, 1), rules.attacker_speed * terrain, "control"),
            Player((2, 3), rules.defender_speed * terrain, "disturbance"),
        )
    )


def _shift(geometry: CtfGeometry) -> float:
    return EDGE_SLACK * min(geometry.grid.spacing)


def _attacker_part(a: np.ndarray, dtype) -> np.ndarray:
    return np.asarray(a, dtype)[:, :, None, None]


def _defender_part(b: np.ndarray, dtype) -> np.ndarray:
    return np.asarray(b, dtype)[None, None, :, :]


def _avoid(geometry: CtfGeometry, rules: Rules, dtype) -> PaddedField:
    """``C_J = C u G_A``: captured, or the attacker blocked."""
    avoid = PaddedField(geometry.joint_grid(), dtype)
    xs, ys = (np.asarray(v, dtype) for v in geometry.grid.axes())
    dx = xs[:, None, None, None] - xs[None, None, :, None]
    dy = ys[None, :, None, None] - ys[None, None, None, :]
    np.hypot(dx, dy, out=avoid.nodes)
    avoid.nodes -= dtype.type(rules.capture_radius)
    np.minimum(avoid.nodes, _attacker_part(geometry.blocked + _shift(geometry), dtype), out=avoid.nodes)
    return avoid


def _defender_forfeits(geometry: CtfGeometry) -> np.ndarray:
    """``G_D`` on the defender's plane: in F, in R or blocked."""
    return np.minimum(np.minimum(geometry.flag, geometry.home), geometry.blocked + _shift(geometry))


def _target(name: str, geometry: CtfGeometry, forfeit: np.ndarray, sets: dict[str, SetSolution], dtype) -> PaddedField:
    """The attacker's target of one set, ``G_x u G_D``."""
    target = PaddedField(geometry.joint_grid(), dtype)
    defender_forfeits = _defender_part(forfeit, dtype)
    if name == "return":
        np.minimum(_attacker_part(geometry.home, dtype), defender_forfeits, out=target.nodes)
    elif name == "capture":
        np.minimum(_attacker_part(geometry.flag, dtype), defender_forfeits, out=target.nodes)
    else:
        # W_A: the flag reached inside R_A, i.e. max(l_F, J_RA); or a forfeit.
        np.maximum(_attacker_part(geometry.flag, dtype), sets["return"].value, out=target.nodes)
        np.minimum(target.nodes, defender_forfeits, out=target.nodes)
    return target
