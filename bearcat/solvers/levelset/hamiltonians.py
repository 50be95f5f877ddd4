"""Hamiltonians for the level-set solver of ``solvers.levelset.hji``.

The control (the attacker of thesis ch. 3) minimises, the disturbance (the
defender) maximises: ``H(x, p) = min_u max_d p . f(x, u, d)`` (thesis
eq. 3.3). Two families are supported, each lowered to plain arrays (and, for
user dynamics, one compiled function of a fixed signature) so that the
compiled stage kernel is the same machine code for every problem and stays
in numba's on-disk cache:

- ``SimpleMotion``: players that move in any direction of their own axes at
  up to a speed that may vary over their position (thesis 3.1.1, speed maps),
  ``H = sum_players sign * v(x_player) |p_player|`` with sign -1 for the
  control and +1 for the disturbance (eq. 3.7).
- ``ControlAffine``: ``f = f0(x) + G(x) u + K(x) d`` with ``u`` in a box or a
  ball and ``d`` in a box or a ball. Affine dependence on the inputs makes
  the min over ``u`` and the max over ``d`` closed-form (a box's best vertex
  per component, a ball's point along ``-+ G^T p``), so nothing is sampled.
  Dynamics that are not input-affine must be rewritten in this form (e.g. a
  fixed feedback law goes into ``f0``).

Both use Lax-Friedrichs dissipation whose coefficient on axis ``k`` is a bound
on ``|dH/dp_k|`` over all gradients, evaluated at each node (what
hj_reachability calls global Lax-Friedrichs): a player's local speed for
simple motion, ``|f0_k| + |G_k.| u_max + |K_k.| d_max`` for affine dynamics.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np
from numba.core.types.function_type import CompileResultWAP

from bearcat.solvers.errors import InputError, non_negative
from bearcat.solvers.grid import Grid
from bearcat.solvers.levelset import kernels as kern

__all__ = ["DYNAMICS_SIGNATURE", "Ball", "Box", "ControlAffine", "Player", "SimpleMotion"]

DYNAMICS_SIGNATURE = kern.DYNAMICS_SIGNATURE
"""``dynamics(x, f0, G, K)``: float64 state ``x`` (n,) in, fills ``f0`` (n,),
``G`` (n, m) and ``K`` (n, q)."""

ROLES = {"control": -1.0, "disturbance": 1.0}


@dataclass(frozen=True)
class Player:
    """One agent of simple motion on grid ``axes``, at up to ``speed`` (a
    number, or an array over the sub-grid of those axes, in axis order)."""

    axes: tuple[int, ...]
    speed: float | np.ndarray
    role: str = "control"


@dataclass(frozen=True)
class SimpleMotion:
    players: tuple[Player, ...]

    @classmethod
    def pursuit(cls, attacker_speed, defender_speed, dims: int = 2) -> SimpleMotion:
        """The attacker (control) on axes ``0..dims-1`` against the defender
        (disturbance) on the next ``dims`` axes: the game of thesis 3.1."""
        attacker = Player(tuple(range(dims)), attacker_speed, "control")
        defender = Player(tuple(range(dims, 2 * dims)), defender_speed, "disturbance")
        return cls((attacker, defender))


@dataclass(frozen=True)
class Box:
    lo: tuple[float, ...]
    hi: tuple[float, ...]


@dataclass(frozen=True)
class Ball:
    center: tuple[float, ...]
    radius: float


@dataclass(frozen=True)
class ControlAffine:
    """``f(x, u, d) = f0(x) + G(x) u + K(x) d``.

    ``dynamics`` is a numba ``@njit`` function (or a plain Python function,
    which is compiled here) with the signature ``DYNAMICS_SIGNATURE``.
    Declaring it with ``cache=True`` keeps a fresh process from recompiling
    it; the solver's own kernels are cached whatever it is."""

    dynamics: Callable
    control: Box | Ball | None = None
    disturbance: Box | Ball | None = None


class Lowered(NamedTuple):
    """A Hamiltonian as the stage kernel takes it (the first argument is the
    per-axis edge sign of the ghost extrapolation), and the rate
    ``max_x sum_k alpha_k(x) / dx_k`` that bounds the time step."""

    args: tuple
    rate: float

    @property
    def edge_sign(self) -> np.ndarray:
        return self.args[0]


_EMPTY_F = np.zeros(0)


def lower(hamiltonian, grid: Grid, dtype) -> Lowered:
    """``hamiltonian`` checked against ``grid`` and lowered for the kernels
    computing in ``dtype``."""
    if isinstance(hamiltonian, SimpleMotion):
        return _lower_simple_motion(hamiltonian, grid, dtype)
    if isinstance(hamiltonian, ControlAffine):
        return _lower_control_affine(hamiltonian, grid, dtype)
    raise InputError(f"hamiltonian must be a SimpleMotion or a ControlAffine, got {type(hamiltonian).__name__}")


def _lower_simple_motion(h: SimpleMotion, grid: Grid, dtype) -> Lowered:
    if not h.players:
        raise InputError("SimpleMotion needs at least one player")
    axis_player = np.full(grid.ndim, -1, np.int64)
    signs, maps, offsets = [], [], []
    strides = np.zeros((len(h.players), grid.ndim), np.int64)
    rate = 0.0
    offset = 0
    for q, player in enumerate(h.players):
        name = f"player {q}"
        if player.role not in ROLES:
            raise InputError(f"{name} has role {player.role!r}; use 'control' or 'disturbance'")
        axes = tuple(int(k) for k in player.axes)
        if not axes or any(not 0 <= k < grid.ndim for k in axes):
            raise InputError(f"{name} has axes {player.axes} but the grid has {grid.ndim} dimensions")
        for k in axes:
            if axis_player[k] >= 0:
                raise InputError(f"axis {k} belongs to player {axis_player[k]} and to {name}")
            axis_player[k] = q
        sub_shape = tuple(grid.shape[k] for k in axes)
        speed = np.asarray(player.speed, dtype=np.float64)
        if speed.ndim == 0:
            speed = np.full((1,) * len(axes), float(speed))
        elif speed.shape != sub_shape:
            raise InputError(f"{name}'s speed map has shape {speed.shape} but its axes {axes} span {sub_shape}")
        if not np.isfinite(speed).all() or (speed < 0).any():
            raise InputError(f"{name}'s speed must be finite and non-negative everywhere")
        map_strides = np.cumprod((speed.shape[1:] + (1,))[::-1])[::-1]
        for k, s, extent in zip(axes, map_strides, speed.shape):
            strides[q, k] = s if extent > 1 else 0
        signs.append(ROLES[player.role])
        maps.append(speed.ravel())
        offsets.append(offset)
        offset += speed.size
        rate += float(speed.max()) * sum(1.0 / grid.spacing[k] for k in axes)
    # Beyond the edge of a disturbance axis values fall, so the disturbance
    # never gains by leaving; elsewhere they rise against the control.
    edge_sign = np.where(np.asarray(signs, dtype)[axis_player] > 0, -1, 1).astype(dtype)
    edge_sign[axis_player < 0] = 1
    args = (
        edge_sign,
        kern.SIMPLE_MOTION,
        axis_player,
        np.asarray(signs, dtype=dtype),
        np.concatenate(maps).astype(dtype),
        np.asarray(offsets, np.int64),
        strides,
        *_no_tables(grid.ndim, dtype),
        kern.NO_INPUT,
        _EMPTY_F,
        _EMPTY_F,
        kern.NO_INPUT,
        _EMPTY_F,
        _EMPTY_F,
    )
    return Lowered(args, rate)


def _input_set(s, name: str) -> tuple[int, np.ndarray, np.ndarray]:
    """Kernel encoding ``(kind, a, b)`` of an input set; an absent set is an
    input of dimension zero."""
    if s is None:
        return kern.NO_INPUT, _EMPTY_F, _EMPTY_F
    if isinstance(s, Box):
        lo = np.asarray(s.lo, dtype=np.float64).ravel()
        hi = np.asarray(s.hi, dtype=np.float64).ravel()
        if lo.shape != hi.shape or lo.size == 0:
            raise InputError(f"the {name} box needs lo and hi of one equal, non-zero length")
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()) or (lo > hi).any():
            raise InputError(f"the {name} box needs finite lo <= hi, got lo={s.lo} hi={s.hi}")
        return kern.BOX, lo, hi
    if isinstance(s, Ball):
        center = np.asarray(s.center, dtype=np.float64).ravel()
        if center.size == 0 or not np.isfinite(center).all():
            raise InputError(f"the {name} ball needs a finite centre, got {s.center}")
        radius = non_negative(s.radius, f"the {name} ball's radius")
        return kern.BALL, center, np.array([radius])
    raise InputError(f"the {name} set must be a Box, a Ball or None, got {type(s).__name__}")


def compiled_dynamics(fn) -> CompileResultWAP:
    """``fn`` compiled for ``DYNAMICS_SIGNATURE`` as a first-class function
    value: the kernels then take it as a typed function pointer, so their
    cached machine code does not depend on which dynamics is passed."""
    dispatcher = fn if isinstance(fn, numba.core.registry.CPUDispatcher) else numba.njit(fn)
    try:
        dispatcher.compile(DYNAMICS_SIGNATURE.args)
    except Exception as exc:  # numba raises many kinds of typing errors
        name = getattr(fn, "__name__", repr(fn))
        raise InputError(f"dynamics {name} does not compile as dynamics(x, f0, G, K) on float64 arrays: {exc}") from exc
    return CompileResultWAP(dispatcher.get_compile_result(DYNAMICS_SIGNATURE))


def _no_tables(ndim: int, dtype) -> tuple[np.ndarray, ...]:
    """The dynamics tables' slots of the kernels under simple motion, never read."""
    return (
        np.zeros((1, ndim), dtype),
        np.zeros((1, ndim, 0), dtype),
        np.zeros((1, ndim, 0), dtype),
        np.zeros((1, ndim), dtype),
    )


def table_bytes(hamiltonian, grid: Grid, dtype) -> int:
    """Bytes of the tables a control-affine Hamiltonian is lowered with: its
    ``f0``, ``G``, ``K`` and dissipation coefficients at every node."""
    if not isinstance(hamiltonian, ControlAffine):
        return 0
    m = _input_set(hamiltonian.control, "control")[1].size
    q = _input_set(hamiltonian.disturbance, "disturbance")[1].size
    return grid.size * grid.ndim * (2 + m + q) * np.dtype(dtype).itemsize


def _check_fills(fn, grid: Grid, m: int, q: int) -> None:
    """Call the dynamics once at the grid's centre and require every entry of
    ``f0``, ``G`` and ``K`` to be written with a finite number: a function
    written for other input sizes shows up here instead of in the solve."""
    x = (np.asarray(grid.lo) + np.asarray(grid.hi)) / 2
    f0, G, K = np.full(grid.ndim, np.nan), np.full((grid.ndim, m), np.nan), np.full((grid.ndim, q), np.nan)
    fn.cres.entry_point(x, f0, G, K)
    for name, a in (("f0", f0), ("G", G), ("K", K)):
        if not np.isfinite(a).all():
            raise InputError(
                f"dynamics left {name} (shape {a.shape}) unset or non-finite at the grid centre {tuple(x)}; "
                f"it must fill f0 ({grid.ndim},), G ({grid.ndim}, {m}) and K ({grid.ndim}, {q})"
            )


def _lower_control_affine(h: ControlAffine, grid: Grid, dtype) -> Lowered:
    dyn = compiled_dynamics(h.dynamics)
    u = _input_set(h.control, "control")
    d = _input_set(h.disturbance, "disturbance")
    _check_fills(dyn, grid, u[1].size, d[1].size)
    m, q = u[1].size, d[1].size
    tables = (
        np.empty((grid.size, grid.ndim), dtype),
        np.empty((grid.size, grid.ndim, m), dtype),
        np.empty((grid.size, grid.ndim, q), dtype),
        np.empty((grid.size, grid.ndim), dtype),
    )
    lo = np.asarray(grid.lo, dtype=np.float64)
    dx = np.asarray(grid.spacing, dtype=np.float64)
    rate = kern.tabulate(np.asarray(grid.shape, np.int64), lo, dx, dyn, *u, *d, *tables)
    if not math.isfinite(rate):
        raise InputError("dynamics returned a non-finite f0, G or K somewhere on the grid")
    args = (
        np.ones(grid.ndim, dtype),
        kern.CONTROL_AFFINE,
        np.full(grid.ndim, -1, np.int64),
        np.zeros(1, dtype),
        np.zeros(1, dtype),
        np.zeros(1, np.int64),
        np.zeros((1, grid.ndim), np.int64),
        *tables,
        *u,
        *d,
    )
    return Lowered(args, float(rate))
