"""Reach-avoid sets from the time-dependent Hamilton-Jacobi-Isaacs equation
(thesis 3.2), on N-dimensional grids.

The control wants to reach the target ``T = {l <= 0}`` within the horizon
while never entering the avoid set ``K = {g <= 0}``, whatever the
disturbance does. The value ``J`` is integrated backwards from the horizon:
a backward-time step of ``dJ/dt = H(x, dJ/dx)`` followed by

    J <- max(min(J, l), -g)

after every full time step, from ``J = max(l, -g)``. This is the
reach-avoid variational inequality of Fisac et al. (2015), the form
helperOC's ``HJIPDE_solve`` applies with targets and obstacles: ``min`` with
``l`` keeps every state that has reached the target (once in, the game is
won), ``max`` with ``-g`` keeps every state in ``K`` lost, and the avoid set
wins where the two overlap (capture inside the target still loses, as in
thesis 3.3.1). Its zero sub-level set is the thesis's eq. 3.3, whose
``min[0, H]`` instead freezes ``J`` wherever it would rise; this form lets
the interior keep the game value ``min_t l(x(t))`` (subject to avoiding
``K``), so gradients inside the set, and the strategies of eqs. 3.12-3.13
drawn from them, stay meaningful. The reach-avoid set over the horizon is
``{J <= 0}``.

Numerics: WENO5 one-sided derivatives with third-order TVD Runge-Kutta
(``scheme="weno5"``) or first-order upwind differences with forward Euler
(``scheme="first"``), a Lax-Friedrichs numerical Hamiltonian (see
``solvers.levelset.hamiltonians``), and a fixed step ``dt = cfl / max_x sum_k
alpha_k(x) / dx_k``: the dissipation bounds depend on the state only, so the
step is found once. The schemes are hj_reachability's
``SolverSettings.with_accuracy("very_high")`` and ``("low")``. They run on
the CPU's cores (``levelset.kernels``) or on a CUDA GPU (``levelset.cuda``), as
``device`` says (``solvers.levelset.devices``).

Grid edges are the edges of the state space, where nobody gains by leaving.
Values beyond an edge are extrapolated linearly with the edge slope's
magnitude (``levelset.kernels._beyond``): rising beyond the edges of the axes the
control moves along, so leaving never helps it reach the target, and, for
simple motion, falling beyond the disturbance's axes, so leaving never helps
it either; these are the rules of thesis 3.3.1 (an attacker that leaves the
area loses, a defender that leaves forfeits) and, for general dynamics, the
conservative side of the control's guarantee. The usual alternative,
extrapolating away from zero, lets a player gain without bound by heading
out of the grid, so values inside the sets drift for ever and a solve never
converges. The edge rows are ordinary nodes of the area: a target touching
the edge is a target up to its last row (the ``min`` with ``l`` holds it
there) and is reached from the rows next to it. Leaving the area is a loss
through the edge rule alone, so ``avoid`` need not (and must not, on rows
that lie in the target) mark the edge rows.

The solve stops early once ``|J(t) - J(t - check_every)|_inf < tol``
(thesis 3.3.2); the result says whether and when. WENO5 settles into small
oscillations near kinks of ``J``, around 1e-2 per half time unit on unit-size
problems, so ``tol`` is in value units and should sit above that.
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba
import numpy as np

from bearcat.solvers.errors import InputError, fraction, non_negative, positive
from bearcat.solvers.grid import Grid
from bearcat.solvers.levelset import devices
from bearcat.solvers.levelset import kernels as kern
from bearcat.solvers.levelset.devices import DEVICES, Device, choose_device
from bearcat.solvers.levelset.hamiltonians import lower, table_bytes

if TYPE_CHECKING:
    from bearcat.solvers.levelset.cuda import GpuSolve

__all__ = ["DEVICES", "SCHEMES", "PaddedField", "ReachAvoidResult", "required_bytes", "solve_reach_avoid"]


@dataclass(frozen=True)
class _Scheme:
    order: int  # of the spatial derivatives
    stages: int  # Runge-Kutta stages per step
    buffers: int  # value-sized arrays the time stepping needs
    band: int  # rows of a local solve's band each side of the front (see _NarrowBand)


# The band holds the WENO5 stencil's three cells and two more for the
# front's motion. First order reads one cell but diffuses more: the clamp's
# edge (``_NarrowBand``) must lie farther out, and with 8 rows T* on the line
# game of Fig. 3.2 was up to 1.8 steps late, with 10 within a step.
SCHEMES = {"weno5": _Scheme(5, 3, 3, 5), "first": _Scheme(1, 1, 2, 10)}

# (a, b) of each stage out = a * u0 + b * (v + dt L(v)) (Shu & Osher 1988).
_SHU_OSHER = {1: ((0.0, 1.0),), 3: ((0.0, 1.0), (0.75, 0.25), (1.0 / 3.0, 2.0 / 3.0))}

# Both schemes are stable up to cfl = 1 (the Euler step is then monotone);
# 0.75 is hj_reachability's default for every accuracy.
DEFAULT_CFL = 0.75


@dataclass(frozen=True)
class ReachAvoidResult:
    """``value`` is ``J`` at the end of the backward integration, after
    ``time`` units (the horizon, or less if it converged) and ``steps`` time
    steps. ``converged_at`` is the time at which a whole ``check_every``
    window changed ``J`` by less than ``tol``, or None.

    With ``record_tstar``, ``tstar`` holds per node the backward time at which
    the node entered the set (linearly interpolated within the step; 0 inside
    the initial set, inf if never) and ``tstar_gradient`` (shape
    ``grid.shape + (ndim,)``) the central gradient of ``J`` at that moment,
    from which eqs. 3.12-3.13 give the controls where the interior value is
    unreliable (end of thesis 3.4); ``record_gradient=False`` leaves it out
    (None) to save ``ndim`` arrays, for callers that take the direction from
    the gradient of ``tstar`` itself, the time-to-reach whose level sets are
    the fronts (eq. 3.6).

    ``node_updates`` counts node time steps (each of ``stages`` Runge-Kutta
    stages): ``grid.size * steps`` on the full grid, less for a ``local``
    solve. ``ceiling`` is None on the full grid; on a local solve, the
    value at which values above the set are clamped (``solve_reach_avoid``
    says what that leaves right). ``device`` names what solved it
    (``solvers.levelset.devices.Device``)."""

    value: np.ndarray
    converged: bool
    converged_at: float | None
    time: float
    steps: int
    node_updates: int = 0
    ceiling: float | None = None
    tstar: np.ndarray | None = None
    tstar_gradient: np.ndarray | None = None
    device: str = "the CPU"

    @property
    def reach_avoid_set(self) -> np.ndarray:
        return self.value <= 0

    @property
    def local(self) -> bool:
        return self.ceiling is not None


class PaddedField:
    """A target or avoid function laid out as the solver keeps it (three
    ghost nodes each side of the last two axes), so a caller can build it in
    place and hand it over without the copy a plain array costs: on a 65^4
    grid that copy is 71 MB per function. Write through ``nodes``, the N-D
    view of the grid nodes."""

    def __init__(self, grid: Grid, dtype=np.float32) -> None:
        na, nb = grid.shape[-2:]
        self.grid = grid
        self.flat = np.zeros(grid.size // (na * nb) * (na + 6) * (nb + 6), np.dtype(dtype))
        self.nodes = _padded_view(self.flat, grid)


def required_bytes(
    grid: Grid,
    *,
    scheme: str = "weno5",
    dtype=np.float32,
    has_avoid: bool = True,
    record_tstar: bool = False,
    record_gradient: bool = True,
) -> int:
    """Bytes of the arrays a solve allocates: the time-stepping buffers, the
    convergence snapshot and its copies of ``target`` and ``avoid`` (all
    padded with three ghost nodes each side of the last two axes), and the
    optional T* record. The result replaces the buffers at the end."""
    na, nb = grid.shape[-2:]
    padded = grid.size // (na * nb) * (na + 6) * (nb + 6)
    n_padded = _scheme(scheme).buffers + 2 + int(has_avoid)
    n_plain = (1 + grid.ndim * int(record_gradient)) if record_tstar else 0
    return (n_padded * padded + n_plain * grid.size) * np.dtype(dtype).itemsize


def available_bytes() -> int:
    """Physical memory not in use now."""
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def solve_reach_avoid(
    grid: Grid,
    hamiltonian,
    target,
    avoid=None,
    *,
    horizon: float,
    scheme: str = "weno5",
    cfl: float = DEFAULT_CFL,
    dtype=np.float32,
    tol: float = 1e-2,
    check_every: float = 0.5,
    record_tstar: bool = False,
    record_gradient: bool = True,
    monotone: bool = True,
    progress: Callable[[float, float], None] | None = None,
    memory_limit: int | None = None,
    local: bool = False,
    device: str = "auto",
) -> ReachAvoidResult:
    """The reach-avoid set of ``target`` (``l``, <= 0 inside) avoiding
    ``avoid`` (``g``, <= 0 inside; None for none) within ``horizon``.

    ``hamiltonian`` is a ``solvers.levelset.hamiltonians.SimpleMotion`` or
    ``ControlAffine``; ``target`` and ``avoid`` are arrays of the grid's
    shape or ``PaddedField``s, which are used without a copy. Time and values are in the units of the dynamics and of
    ``l`` and ``g``: ``tol`` is a value change over ``check_every`` time units
    (0 integrates to the horizon). ``progress(t, change)`` is called after
    every check with the time reached and the last window's change.
    ``monotone`` keeps ``J`` from rising from one step to the next. The
    exact value never rises as the horizon grows (more time only gives the
    control more ways to win), so a rise is the scheme's error: WENO5 is not
    monotone and, near kinks where a capture disk meets a target's edge,
    settles into a ripple of a tenth of a cell or more that never passes
    the convergence check. Dropping rises is the freeze of thesis eq. 3.3's
    ``min[0, H]``; it keeps any dip of that ripple, so the set may gain a
    band as thin as the ripple. ``memory_limit`` (bytes) defaults to the free physical memory; a grid
    whose arrays would not fit (``required_bytes``) is refused before
    anything is allocated. Grids need at least two dimensions.

    ``local`` updates only a narrow band around the front (``_NarrowBand``;
    Adalsteinsson and Sethian 1995, Peng et al. 1999). The set and T* (with
    its gradient) are the full grid's up to a cell and a step, but for the
    few nodes the front passes at a tangent, where T* is as uncertain on
    the full grid itself. Other values are the full grid's only near the
    front: above the set they are clamped at ``ReachAvoidResult.ceiling``,
    a few cells of the value's rise out, so a value there means "at least
    that much" and its gradient, which is zero, names no direction; inside
    the set, beyond the band, they are the last the band gave, less deep
    than the full grid's. Regions, polygons, winners, T* and headings
    drawn from T* are right everywhere; headings drawn from the value's
    gradient outside the set only where the value is below the ceiling.

    ``device`` is ``"cpu"``, ``"cuda"`` (the kernels of
    ``solvers.levelset.cuda`` on a GPU, through numba-cuda) or ``"auto"`` (a GPU
    if numba-cuda finds one and the problem suits it, else the CPU; the
    choice is logged, and ``ReachAvoidResult.device`` names it). Both solve
    the same scheme and give the same sets, but for nodes on the front that
    rounding puts on the other side of zero. The narrow band (``local``)
    runs on the CPU only; ``"cuda"`` without a GPU is an InputError."""
    if not isinstance(grid, Grid):
        raise InputError(f"grid must be a solvers.grid.Grid, got {type(grid).__name__}")
    sch = _scheme(scheme)
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise InputError(f"dtype must be float32 or float64, got {dtype}")
    horizon = positive(horizon, "horizon")
    check_every = positive(check_every, "check_every")
    cfl = fraction(cfl, "cfl")
    tol = non_negative(tol, "tol")
    if grid.ndim < 2:
        raise InputError(f"the grid must have at least 2 dimensions, got {grid.ndim}")
    target = _grid_field("target", target, grid, dtype)
    avoid = None if avoid is None else _grid_field("avoid", avoid, grid, dtype)
    limit = available_bytes() if memory_limit is None else int(memory_limit)
    need = required_bytes(
        grid,
        scheme=scheme,
        dtype=dtype,
        has_avoid=avoid is not None,
        record_tstar=record_tstar,
        record_gradient=record_gradient,
    ) + table_bytes(hamiltonian, grid, dtype)
    if need > limit:
        dims = "x".join(str(n) for n in grid.shape)
        raise InputError(
            f"grid {dims} ({grid.size:,} nodes) needs about {need / 1e9:.2f} GB for the {scheme} solve "
            f"in {dtype.name} but only {limit / 1e9:.2f} GB of memory is available"
        )
    _check_finite("target", _nodes(target))
    if avoid is not None:
        _check_finite("avoid", _nodes(avoid))

    ham = lower(hamiltonian, grid, dtype)
    chosen = _device(device, local, grid, ham.args)
    dt_max = cfl / ham.rate if ham.rate > 0 else check_every

    target = _padded(target, grid, dtype)
    avoid = None if avoid is None else _padded(avoid, grid, dtype)
    if avoid is None:
        u = target.copy()
    else:
        u = np.negative(avoid)
        np.maximum(u, target, out=u)
    band = _NarrowBand(grid, sch.band, u, avoid) if local else None
    if band is not None:
        band.clamp(u, avoid)
    kern.fill_ghosts(u, np.asarray(grid.shape, np.int64), ham.edge_sign)
    with_gradient = record_tstar and record_gradient
    solve: _CpuSolve | GpuSolve
    if chosen.kind == "cuda":
        from bearcat.solvers.levelset import cuda as hji_cuda

        hji_cuda.check_memory(need, str(chosen), grid)
        solve = hji_cuda.GpuSolve(
            grid,
            sch,
            _SHU_OSHER[sch.stages],
            dtype,
            target,
            avoid,
            u,
            ham.args,
            record_tstar,
            with_gradient,
            monotone,
        )
    else:
        solve = _CpuSolve(grid, sch, dtype, target, avoid, u, ham.args, record_tstar, with_gradient, monotone, band)
    del u
    t, steps, converged_at, updates = 0.0, 0, None, 0
    with solve:
        while t < horizon and converged_at is None:
            window = min(check_every, horizon - t)
            n_steps = max(1, math.ceil(window / dt_max - 1e-9))
            dt = window / n_steps
            solve.mark()
            for k in range(n_steps):
                updates += solve.step(dt, t + k * dt)
            steps += n_steps
            t += window
            change = solve.change()
            if math.isnan(change):
                raise InputError(
                    f"the value function stopped being finite by t = {t:g}: the dynamics are too fast for the "
                    "grid's numbers (an overflow), so no set was computed"
                )
            if progress is not None:
                progress(t, change)
            if window >= check_every and change < tol:
                converged_at = t

    value, tstar, tgrad = solve.result()
    del solve, target, avoid
    return ReachAvoidResult(
        value=_unpadded(value, grid),
        converged=converged_at is not None,
        converged_at=converged_at,
        time=t,
        steps=steps,
        node_updates=updates,
        ceiling=None if band is None else band.cap,
        tstar=None if tstar is None else tstar.reshape(grid.shape),
        tstar_gradient=None if tgrad is None else tgrad.reshape(grid.shape + (grid.ndim,)),
        device=str(chosen),
    )


def _device(device: str, local: bool, grid: Grid, ham_args: tuple) -> Device:
    """The device to solve on (``solvers.levelset.devices.choose_device``): the CPU
    for the narrow band, and for a problem the CUDA kernels do not take."""
    if device not in DEVICES:
        raise InputError(f"device must be one of {', '.join(DEVICES)}, got {device!r}")
    if device == "cpu":
        return choose_device(device)
    if local:
        return choose_device(device, unsupported="the narrow band (local) runs on the CPU only")
    if isinstance(devices.find_gpu(), str):
        return choose_device(device)  # no GPU: the CPU, or a refusal, without importing the kernels
    from bearcat.solvers.levelset import cuda as hji_cuda

    return choose_device(device, unsupported=hji_cuda.unsupported(grid.ndim, ham_args))


class _CpuSolve:
    """A solve's arrays in host memory, stepped by the CPU kernels on a pool
    of threads (and, for a local solve, the narrow band around the front)."""

    def __init__(self, grid, sch, dtype, target, avoid, initial, ham_args, record, with_gradient, monotone, band):
        # Copies rather than empty arrays, so no buffer ever holds uninitialised
        # values that the convergence check would read.
        self.buffers = [initial] + [initial.copy() for _ in range(sch.buffers - 1)]
        self.snapshot = initial.copy()
        self.record, self.with_gradient = record, with_gradient
        self.tstar = np.full(grid.size, np.inf, dtype) if record else np.zeros(0, dtype)
        self.tgrad = np.zeros(grid.size * grid.ndim, dtype) if with_gradient else np.zeros(0, dtype)
        self.stepper = _Stepper(grid, sch, dtype, target, avoid, ham_args, record, self.tstar, self.tgrad, monotone)
        self.band = band

    def __enter__(self) -> _CpuSolve:
        self.pool = ThreadPoolExecutor(max_workers=self.stepper.threads)
        return self

    def __exit__(self, *exc) -> None:
        self.pool.shutdown()

    def mark(self) -> None:
        """Take the snapshot the next convergence check compares with."""
        np.copyto(self.snapshot, self.buffers[0])

    def step(self, dt: float, t: float) -> int:
        """One time step from time ``t``; the node updates it made."""
        if self.band is not None:
            self.band.rebuild(self.pool, self.buffers, self.stepper)
        self.stepper.step(self.pool, self.buffers, dt, t)
        return self.stepper.nodes

    def change(self) -> float:
        """``max |J - snapshot|`` over the padded arrays; NaN if either holds
        a number that is not finite."""
        return float(kern.max_abs_difference(self.buffers[0], self.snapshot))

    def result(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """The value (padded), T* and its gradient (None if not recorded)."""
        return self.buffers[0], self.tstar if self.record else None, self.tgrad if self.with_gradient else None


class _Stepper:
    """Runs the stage kernel over the planes of the grid, split between
    threads in contiguous ranges."""

    def __init__(self, grid, sch, dtype, target, avoid, ham_args, record, tstar, tgrad, monotone):
        self.stages = sch.stages
        self.monotone = monotone
        self.dtype = dtype
        self.record = record
        self.fixed = (
            target,
            avoid if avoid is not None else target,
            avoid is not None,
            np.asarray(grid.shape, np.int64),
            np.asarray([1.0 / h for h in grid.spacing], dtype),
            sch.order,
            kern.constants(dtype),
            *ham_args,
        )
        self.tstar, self.tgrad = tstar, tgrad
        self.threads = max(1, numba.get_num_threads())
        self.row_length = grid.shape[-1]
        self.use(kern.plane_blocks(grid.shape))

    def use(self, blocks: np.ndarray) -> None:
        """Update the rows of ``blocks`` from now on, split between the
        threads in ranges of about equal row counts that end at a plane's
        end (the kernel refreshes a plane's ghosts after its last block)."""
        self.blocks = blocks
        rows = int(blocks[:, 2].sum())
        self.nodes = rows * self.row_length
        if len(blocks) == 0:  # a set that is empty or fills the grid has no front
            self.ranges = [(0, 0)]
            return
        ends = np.flatnonzero(np.diff(blocks[:, 0], append=-1)) + 1  # block index after each plane
        done = np.cumsum(blocks[:, 2])[ends - 1]  # rows up to each plane's end
        cuts = ends[np.searchsorted(done, rows * np.arange(1, self.threads) / self.threads)]
        bounds = sorted({0, *(int(c) for c in cuts), len(blocks)})
        self.ranges = list(itertools.pairwise(bounds))

    def step(self, pool, buffers, dt: float, t: float) -> None:
        """One time step from time ``t``; the new value ends up in ``buffers[0]``."""
        u = buffers[0]
        sources = buffers[: self.stages]
        outs = (buffers[1:] + buffers[1:2])[: self.stages]
        cast = self.dtype.type
        for i, ((a, b), v, out) in enumerate(zip(_SHU_OSHER[self.stages], sources, outs)):
            final = i == self.stages - 1
            args = (
                self.blocks,
                v,
                u,
                out,
                cast(a),
                cast(b),
                cast(dt),
                final,
                self.monotone,
                *self.fixed,
                self.record and final,
                t,
                self.tstar,
                self.tgrad,
            )
            if len(self.ranges) == 1:
                kern.stage(*self.ranges[0], *args)
            else:
                for f in [pool.submit(kern.stage, *r, *args) for r in self.ranges]:
                    f.result()
        buffers[0], buffers[1] = buffers[1], buffers[0]


class _NarrowBand:
    """The nodes a local solve updates: whole rows of the grid, those within
    ``radius`` rows (along every axis but the last at once) of a row that
    the zero level crosses, rebuilt before every step. The front moves less
    than a cell per step (the CFL bound), so it never leaves the band, and
    the next front is sought inside the band only. The whole zero level
    counts, walls of the avoid set included: a front can creep along such a
    wall, and leaving the wall out lost a strip of the first-order line game
    of Fig. 3.2.

    Values the band no longer moves must be those that moving them would
    give, or the front, meeting them at the band's edge, goes astray: left
    as they were, the values ahead of the front stayed as far above the
    full grid's as the front had come, and over a 20 s solve of the open
    square the front lagged by up to 66 steps. So the initial value is
    clamped from above at ``cap``, as Peng et al. clamp theirs at the band's
    edge: a flat value stays flat under the Hamiltonian, so values beyond
    the band are the same whether updated or not, and the clamp's edge,
    ``radius`` cells of the value's rise at its zero level out, lies in the
    band, where it moves like any other level (``SCHEMES`` says how far out
    each scheme needs it). ``cap`` is never below the avoid set's highest
    ``-g``, the band widening to match: a ridge above the clamp would slope
    the wrong way round its wall, along which fronts creep. Below zero
    nothing is clamped: beyond the band the set's interior stays less deep
    than the full grid's, which the front, moving outward, does not read.

    Whole rows keep the kernel's loops long: a block costs about 0.7 us
    more than its nodes however short it is (measured on 35^4 grids), so
    bands cut to the node would cost more than they save."""

    def __init__(self, grid: Grid, radius: int, initial: np.ndarray, avoid) -> None:
        self.grid = grid
        self.shape = np.asarray(grid.shape, np.int64)
        self.radius = radius
        rise = _front_slope(_padded_view(initial, grid))
        self.cap = self.radius * rise
        ridge = -float(np.min(_padded_view(avoid, grid))) if avoid is not None else -math.inf
        if ridge > self.cap:
            self.cap = ridge
            self.radius = math.ceil(ridge / rise - 1e-6)
        self.rows = np.zeros(grid.shape[:-1], np.uint8)
        self.band = np.ones(grid.shape[:-1], np.uint8)

    def clamp(self, u: np.ndarray, avoid) -> None:
        """Clamp the initial value ``u`` (padded, before its ghosts are
        made) at ``cap``, the avoid rule kept."""
        np.minimum(u, self.cap, out=u)
        if avoid is not None:
            np.maximum(u, np.negative(avoid), out=u)

    def rebuild(self, pool, buffers, stepper) -> None:
        self.rows[...] = 0
        planes, n = self.rows.size // self.grid.shape[-2], stepper.threads
        cuts = [(i * planes // n, (i + 1) * planes // n) for i in range(n)]
        # A row pair across planes may be marked from both sides of a cut:
        # the marks are idempotent bytes, so the race is harmless.
        self._each(pool, cuts, kern.front_rows, buffers[0], self.shape, self.band.reshape(-1), self.rows.reshape(-1))
        band = _dilated(self.rows, self.radius)
        # Rows leaving the band keep their value; the stage buffers must
        # hold it too, since stencils of band nodes read them there.
        leaving = (self.band > band).view(np.uint8).reshape(-1)
        for b in buffers[1:]:
            self._each(pool, cuts, kern.copy_rows, buffers[0], b, leaving, self.shape)
        self.band = band
        stepper.use(kern.row_blocks(band.reshape(-1), self.shape))

    @staticmethod
    def _each(pool, cuts, kernel, *args) -> None:
        for f in [pool.submit(kernel, *c, *args) for c in cuts]:
            f.result()


def _dilated(rows: np.ndarray, radius: int) -> np.ndarray:
    from scipy import ndimage  # a third of a second to import, which only a local solve needs

    for axis in range(rows.ndim):
        rows = ndimage.maximum_filter1d(rows, 2 * radius + 1, axis=axis, mode="constant")
    return rows


def _front_slope(u: np.ndarray) -> float:
    """The rise of ``u`` over one cell at its zero level: the 90th
    percentile, over pairs of neighbours on either side of zero along any
    axis, of their difference (1 when the grid has no such pair)."""
    pairs = []
    for axis in range(u.ndim):
        below = np.moveaxis(u, axis, 0)
        a, b = below[:-1], below[1:]
        crossing = (a <= 0) != (b <= 0)
        pairs.append(np.abs(b[crossing] - a[crossing]))
    rises = np.concatenate(pairs)
    return float(np.percentile(rises, 90)) if rises.size else 1.0


def _scheme(name: str) -> _Scheme:
    try:
        return SCHEMES[name]
    except (KeyError, TypeError):
        raise InputError(f"scheme must be one of {sorted(SCHEMES)}, got {name!r}") from None


def _grid_field(name: str, a, grid: Grid, dtype):
    """``a`` checked against the grid: a PaddedField as it is, anything else as an array."""
    if isinstance(a, PaddedField):
        if a.grid != grid or a.flat.dtype != dtype:
            raise InputError(f"{name} is a PaddedField for another grid or precision than the solve's")
        return a
    a = np.asarray(a)
    if a.shape != grid.shape:
        raise InputError(f"{name} has shape {a.shape} but the grid has shape {grid.shape}")
    if not np.issubdtype(a.dtype, np.floating) and not np.issubdtype(a.dtype, np.integer):
        raise InputError(f"{name} must hold numbers, got dtype {a.dtype}")
    return a


def _check_finite(name: str, a: np.ndarray) -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        what = "NaN" if np.isnan(a[first]) else "infinite"
        raise InputError(f"{name} has {int(bad.sum())} non-finite values, the first {what} at node {first}")


def _padded_view(flat: np.ndarray, grid: Grid) -> np.ndarray:
    """The grid nodes of a padded flat array, as an N-D view."""
    na, nb = grid.shape[-2:]
    return flat.reshape(grid.shape[:-2] + (na + 6, nb + 6))[..., 3:-3, 3:-3]


def _nodes(a) -> np.ndarray:
    return a.nodes if isinstance(a, PaddedField) else a


def _padded(a, grid: Grid, dtype) -> np.ndarray:
    if isinstance(a, PaddedField):
        return a.flat
    na, nb = grid.shape[-2:]
    flat = np.zeros(grid.size // (na * nb) * (na + 6) * (nb + 6), dtype)
    _padded_view(flat, grid)[...] = a
    return flat


def _unpadded(flat: np.ndarray, grid: Grid) -> np.ndarray:
    return np.ascontiguousarray(_padded_view(flat, grid))
