"""CUDA kernels of the level-set solver in ``solvers.levelset.hji``, and the arrays
they keep on the GPU between steps; numba-cuda compiles them.

Importing this module imports numba-cuda (``pip install 'bearcat[cuda]'``):
``solvers.levelset.hji`` does so only for a solve on device ``"cuda"``
(``solvers.levelset.devices``). Under numba's CUDA simulator the same kernels run
on the CPU, which is how they are tested without a GPU.

The arrays are the CPU solver's, padded alike (three ghost nodes each side
of the last two axes, ``levelset.kernels``), so the fields a caller built in
place go to the GPU as they are and the value comes back as the CPU
returns it. The kernels:

- ``_stage``, one Runge-Kutta stage fused: per node, the derivatives along
  every axis, the numerical Hamiltonian, its dissipation, the Shu-Osher
  combination and, in the last stage of a step, the monotone clamp, the
  reach-avoid update and the T* record. One thread per grid node (a
  grid-stride loop, so a launch of any size covers the grid); neighbours
  beyond the grid's edge along any axis are made up from the edge as they
  are read (``levelset.kernels._beyond``), so no ghost is stored and no second
  kernel runs per stage.
- ``_max_change``, the convergence check: ``max |u - snapshot|`` over the
  padded arrays, ghost entries included with the values the CPU's
  ``_fill_ghosts`` would store there, so that both backends stop at the same
  window; a block-wide reduction and one atomic per block.

The arithmetic is the CPU kernels' own wherever numba lets it be: the WENO5
weights (``_weno5``), the ghost rule (``_beyond``), the control-affine
Hamiltonian (``_affine_hamiltonian``, with ``_input_extremum``) and T*'s
entry time (``_entry_time``) are the ``@njit`` functions of
``levelset.kernels``, which numba-cuda compiles for the GPU when a kernel calls
them. What is written again here is what the CPU kernels evaluate over
whole runs of a plane, so that their loops vectorise, and a GPU thread
evaluates at one node: the divided differences, the simple-motion
Hamiltonian (``levelset.kernels._simple_motion_block``), the Runge-Kutta
combination and the clamps (``levelset.kernels.stage``), each the same formula
in the same order of operations.

numba's on-disk cache checks only the file of the cached function, so a
change to a shared function in ``levelset.kernels`` would not reach the cached
kernels by itself: ``SHARED_SOURCE`` records a hash of the shared functions'
source, and while it does not match (a test says when), the kernels are
compiled afresh in each process instead of cached.
"""

from __future__ import annotations

import hashlib
import inspect
import math

import numpy as np
from numba import cuda, float64, int64, njit
from numba.core import config

from bearcat.solvers.errors import InputError
from bearcat.solvers.levelset import kernels as kern

SIMULATED = bool(getattr(config, "ENABLE_CUDASIM", 0))
"""Whether numba runs CUDA kernels in its simulator (``NUMBA_ENABLE_CUDASIM=1``)."""

MAX_DIMS = 8
"""Most state dimensions the kernels take (the sizes of their per-thread arrays)."""
MAX_INPUTS = 8
"""Most control or disturbance components the kernels take."""
THREADS = 128
"""Threads per block of the stage kernel."""
# The simulator runs a Python thread per CUDA thread: a few threads striding
# over the grid run the same kernel far faster than one per node.
SIMULATED_LAUNCH = (2, 2)
REDUCE_THREADS = 4 if SIMULATED else 256
"""Threads per block of the convergence check (a power of two)."""
REDUCE_BLOCKS = 1024

SHARED = (kern._weno5, kern._beyond, kern._affine_hamiltonian, kern._input_extremum, kern._entry_time)
"""The ``levelset.kernels`` functions the CUDA kernels call."""
SHARED_SOURCE = "b0efba7c5b769c86"
"""``shared_source()`` when the kernels were last checked against ``SHARED``."""


def shared_source() -> str:
    """A hash of the source of the ``SHARED`` functions ('' if it cannot be read)."""
    try:
        text = "\n".join(inspect.getsource(f.py_func) for f in SHARED)
    except (OSError, TypeError):
        return ""
    return hashlib.sha256(text.encode()).hexdigest()[:16]


_CACHE = not SIMULATED and shared_source() == SHARED_SOURCE


def _device(function):
    """A ``numba.njit`` function as the kernels call it: numba-cuda compiles
    it for the GPU when a kernel calls it; the simulator, which runs kernels
    as Python with an array type compiled CPU code cannot take, calls its
    Python source."""
    return function.py_func if SIMULATED else function


def _helper(function):
    """A function of this module's kernels, compiled as ``_device`` says."""
    return _device(njit(function))


_weno5 = _device(kern._weno5)
_beyond = _device(kern._beyond)
_affine_hamiltonian = _device(kern._affine_hamiltonian)
_entry_time = _device(kern._entry_time)


@_helper
def _along(v, pos, i, o, size, stride, sign, scratch):
    """The value ``o`` nodes along an axis from the node at ``pos``, whose
    index along that axis is ``i`` of ``size`` (``stride`` apart); beyond
    the edge it is made up from the edge as the CPU's ghosts are, and
    rounded, through ``scratch``, to the values' precision as a stored
    ghost is."""
    j = i + o
    if j < 0:
        e = pos - i * stride
        scratch[0] = _beyond(v[e], v[e + stride], -j, sign)
        return scratch[0]
    if j >= size:
        e = pos + (size - 1 - i) * stride
        scratch[0] = _beyond(v[e], v[e - stride], j - size + 1, sign)
        return scratch[0]
    return v[pos + o * stride]


@cuda.jit(cache=_CACHE)
def _stage(
    v,
    u0,
    out,
    a,
    b,
    dt,
    final,
    monotone,
    target,
    avoid,
    has_avoid,
    shape,
    strides,
    inv_dx,
    order,
    consts,
    edge_sign,
    kind,
    axis_player,
    player_sign,
    speed,
    speed_offset,
    speed_stride,
    f0s,
    Gs,
    Ks,
    alphas,
    u_kind,
    u_a,
    u_b,
    d_kind,
    d_a,
    d_b,
    record,
    t_old,
    tstar,
    tgrad,
):
    """One Runge-Kutta stage in Shu-Osher form, ``out = a u0 + b (v + dt
    L(v))``, at every grid node: ``levelset.kernels.stage``'s arithmetic (which
    see, with its arguments) at one node per thread, reading neighbours in
    place. ``strides`` holds the padded offset of one step along each axis;
    ghost entries of ``out`` are left as they are, never read."""
    ndim = shape.shape[0]
    corner = 3 * (shape[ndim - 1] + 6) + 3
    # The grid's geometry as arrays of this thread, read at every node.
    n = cuda.local.array(MAX_DIMS, int64)
    step = cuda.local.array(MAX_DIMS, int64)
    sign = cuda.local.array(MAX_DIMS, v.dtype)
    inv = cuda.local.array(MAX_DIMS, v.dtype)
    size = 1
    for k in range(ndim):
        n[k], step[k], sign[k], inv[k] = shape[k], strides[k], edge_sign[k], inv_dx[k]
        size *= shape[k]
    c = (
        consts[0],
        consts[1],
        consts[2],
        consts[3],
        consts[4],
        consts[5],
        consts[6],
        consts[7],
        consts[8],
        consts[9],
        consts[10],
        consts[11],
        consts[12],
        consts[13],
    )
    half, zero = consts[14], consts[15]
    idx = cuda.local.array(MAX_DIMS, int64)
    g = cuda.local.array(1, v.dtype)
    x = cuda.local.array(2, v.dtype)
    pl = cuda.local.array((MAX_DIMS, 1), v.dtype)
    pr = cuda.local.array((MAX_DIMS, 1), v.dtype)
    spd = cuda.local.array(MAX_DIMS, v.dtype)
    norm = cuda.local.array(MAX_DIMS, v.dtype)
    p = cuda.local.array(MAX_DIMS, float64)
    cu = cuda.local.array(MAX_INPUTS, float64)
    cd = cuda.local.array(MAX_INPUTS, float64)
    # The input sets as arrays of this thread: the shared Hamiltonian reads
    # them as plain arrays on the GPU and in the simulator alike.
    ua = cuda.local.array(MAX_INPUTS, float64)
    ub = cuda.local.array(MAX_INPUTS, float64)
    da = cuda.local.array(MAX_INPUTS, float64)
    db = cuda.local.array(MAX_INPUTS, float64)
    for i in range(u_a.shape[0]):
        ua[i] = u_a[i]
    for i in range(u_b.shape[0]):
        ub[i] = u_b[i]
    for i in range(d_a.shape[0]):
        da[i] = d_a[i]
    for i in range(d_b.shape[0]):
        db[i] = d_b[i]
    for node in range(cuda.grid(1), size, cuda.gridsize(1)):
        rest = node
        pos = corner
        for k in range(ndim - 1, -1, -1):
            idx[k] = rest % n[k]
            rest //= n[k]
            pos += idx[k] * step[k]
        centre = v[pos]
        for k in range(ndim):
            st, i, h = step[k], idx[k], inv[k]
            if order == 1:
                if 0 < i < n[k] - 1:  # both neighbours inside the grid
                    r2, r4 = v[pos - st], v[pos + st]
                else:
                    r2 = _along(v, pos, i, -1, n[k], st, sign[k], g)
                    r4 = _along(v, pos, i, 1, n[k], st, sign[k], g)
                pl[k, 0] = (centre - r2) * h
                pr[k, 0] = (r4 - centre) * h
                continue
            if 3 <= i < n[k] - 3:  # the stencil lies inside the grid
                r0, r1, r2 = v[pos - 3 * st], v[pos - 2 * st], v[pos - st]
                r4, r5, r6 = v[pos + st], v[pos + 2 * st], v[pos + 3 * st]
            else:
                r0 = _along(v, pos, i, -3, n[k], st, sign[k], g)
                r1 = _along(v, pos, i, -2, n[k], st, sign[k], g)
                r2 = _along(v, pos, i, -1, n[k], st, sign[k], g)
                r4 = _along(v, pos, i, 1, n[k], st, sign[k], g)
                r5 = _along(v, pos, i, 2, n[k], st, sign[k], g)
                r6 = _along(v, pos, i, 3, n[k], st, sign[k], g)
            d0 = (r1 - r0) * h
            d1 = (r2 - r1) * h
            d2 = (centre - r2) * h
            d3 = (r4 - centre) * h
            d4 = (r5 - r4) * h
            d5 = (r6 - r5) * h
            pl[k, 0] = _weno5(d0, d1, d2, d3, d4, c)
            pr[k, 0] = _weno5(d5, d4, d3, d2, d1, c)
        if kind == kern.SIMPLE_MOTION:
            dv = _simple_motion(
                idx, pl, pr, half, zero, axis_player, player_sign, speed, speed_offset, speed_stride, spd, norm
            )
        else:
            dv = _affine_hamiltonian(
                pl,
                pr,
                0,
                node,
                f0s,
                Gs,
                Ks,
                alphas,
                u_kind,
                ua[: u_a.shape[0]],
                ub[: u_b.shape[0]],
                d_kind,
                da[: d_a.shape[0]],
                db[: d_b.shape[0]],
                p,
                cu,
                cd,
            )
        # Through an array of the value's precision, as the CPU stores them.
        x[0] = dv
        before = u0[pos]
        x[1] = a * before + b * (centre + dt * x[0])
        if final:
            if monotone:
                x[1] = min(x[1], before)
            x[1] = min(x[1], target[pos])
            if has_avoid:
                x[1] = max(x[1], -avoid[pos])
            if record and x[1] <= 0 and tstar[node] == np.inf:
                tstar[node] = _entry_time(before, x[1], t_old, dt)
                if tgrad.shape[0] != 0:
                    for k in range(ndim):
                        tgrad[node * ndim + k] = 0.5 * (pl[k, 0] + pr[k, 0])
        out[pos] = x[1]


@_helper
def _simple_motion(idx, pl, pr, half, zero, axis_player, player_sign, speed, speed_offset, speed_stride, spd, norm):
    """``levelset.kernels._simple_motion_block`` at one node: the Lax-Friedrichs
    Hamiltonian ``sum_q sign_q v_q |p_q|`` plus each axis's dissipation at
    its player's local speed, summed in the same order."""
    ndim = axis_player.shape[0]
    for q in range(player_sign.shape[0]):
        at = speed_offset[q]
        for k in range(ndim):
            at += idx[k] * speed_stride[q, k]
        spd[q] = speed[at]
        norm[q] = zero
    dv = zero
    for k in range(ndim):
        q = axis_player[k]
        if q < 0:
            continue
        m = half * (pl[k, 0] + pr[k, 0])
        norm[q] += m * m
        dv += half * spd[q] * (pr[k, 0] - pl[k, 0])
    for q in range(player_sign.shape[0]):
        dv += player_sign[q] * spd[q] * math.sqrt(norm[q])
    return dv


@_helper
def _stored(v, start, r, c, na, nb, sign_a, sign_b, scratch):
    """The entry at row ``r``, column ``c`` of the padded plane at ``start``
    as the CPU stores it: a node's value, or the ghost ``_fill_ghosts``
    makes (ghost columns of the rows first, then ghost rows of whole rows),
    each rounded to the array's precision as a stored ghost is."""
    if r < 3:
        scratch[0] = _stored_row(v, start + 3 * (nb + 6), c, nb, sign_b)
        scratch[1] = _stored_row(v, start + 4 * (nb + 6), c, nb, sign_b)
        scratch[0] = _beyond(scratch[0], scratch[1], 3 - r, sign_a)
    elif r >= na + 3:
        scratch[0] = _stored_row(v, start + (na + 2) * (nb + 6), c, nb, sign_b)
        scratch[1] = _stored_row(v, start + (na + 1) * (nb + 6), c, nb, sign_b)
        scratch[0] = _beyond(scratch[0], scratch[1], r - na - 2, sign_a)
    else:
        scratch[0] = _stored_row(v, start + r * (nb + 6), c, nb, sign_b)
    return scratch[0]


@_helper
def _stored_row(v, row, c, nb, sign_b):
    """Entry ``c`` of the padded row of grid nodes beginning at ``row``."""
    if c < 3:
        return _beyond(v[row + 3], v[row + 4], 3 - c, sign_b)
    if c >= nb + 3:
        return _beyond(v[row + nb + 2], v[row + nb + 1], c - nb - 2, sign_b)
    return v[row + c]


@cuda.jit(cache=_CACHE)
def _max_change(u, snapshot, shape, edge_sign, out):
    """``out[0] = max(out[0], max |u - snapshot|)`` over the padded arrays,
    ghosts as the CPU stores them; inf as soon as either holds a number that
    is not finite (``levelset.kernels.max_abs_difference``)."""
    ndim = shape.shape[0]
    na, nb = shape[ndim - 2], shape[ndim - 1]
    plane = (na + 6) * (nb + 6)
    sign_a, sign_b = edge_sign[ndim - 2], edge_sign[ndim - 1]
    x = cuda.local.array(2, u.dtype)
    y = cuda.local.array(2, u.dtype)
    best = 0.0
    for e in range(cuda.grid(1), u.shape[0], cuda.gridsize(1)):
        start = e - e % plane
        r = (e - start) // (nb + 6)
        c = e - start - r * (nb + 6)
        d = abs(
            float64(_stored(u, start, r, c, na, nb, sign_a, sign_b, x))
            - float64(_stored(snapshot, start, r, c, na, nb, sign_a, sign_b, y))
        )
        best = max(best, d) if d < np.inf else np.inf
    shared = cuda.shared.array(REDUCE_THREADS, float64)
    t = cuda.threadIdx.x
    shared[t] = best
    cuda.syncthreads()
    s = REDUCE_THREADS // 2
    while s > 0:
        if t < s:
            shared[t] = max(shared[t], shared[t + s])
        cuda.syncthreads()
        s //= 2
    if t == 0:
        cuda.atomic.max(out, 0, shared[0])


def _padded_strides(shape: tuple[int, ...]) -> np.ndarray:
    """The padded offset of one step along each axis."""
    na, nb = shape[-2:]
    strides = np.ones(len(shape), np.int64)
    strides[-2] = nb + 6
    step = (na + 6) * (nb + 6)
    for k in range(len(shape) - 3, -1, -1):
        strides[k] = step
        step *= shape[k]
    return strides


def unsupported(ndim: int, ham_args: tuple) -> str | None:
    """Why a problem of ``ndim`` dimensions and this lowered Hamiltonian
    cannot run on these kernels, or None."""
    if ndim > MAX_DIMS:
        return f"the CUDA kernels take at most {MAX_DIMS} dimensions, the grid has {ndim}"
    inputs = max(ham_args[12].size, ham_args[15].size)
    if inputs > MAX_INPUTS:
        return f"the CUDA kernels take at most {MAX_INPUTS} input components, the dynamics have {inputs}"
    return None


def free_bytes() -> float:
    """GPU memory not in use now (infinite in the simulator), once the arrays
    of earlier solves that numba has yet to free are freed."""
    context = cuda.current_context()
    pending = getattr(context, "deallocations", None)
    if pending is not None:
        pending.clear()
    return float(context.get_memory_info().free)


class GpuSolve:
    """A solve's arrays on the GPU, and the kernels that step them: the
    value buffers, the convergence snapshot, the target and avoid functions,
    the lowered Hamiltonian and T*, uploaded once; only the value and T*
    come back, at the end (``result``), and one number per convergence
    check. The interface of ``solvers.levelset.hji._CpuSolve``."""

    def __init__(
        self,
        grid,
        scheme,
        coefficients,
        dtype,
        target,
        avoid,
        initial,
        ham_args,
        record,
        gradient,
        monotone,
    ):
        self.grid = grid
        self.stages = scheme.stages
        self.coefficients = coefficients
        self.dtype = np.dtype(dtype)
        self.record, self.with_gradient = record, gradient
        first = cuda.to_device(initial)
        self.buffers = [first] + [_copy(first) for _ in range(scheme.buffers - 1)]
        self.snapshot = _copy(first)
        self.target = cuda.to_device(target)
        self.avoid = self.target if avoid is None else cuda.to_device(avoid)
        self.has_avoid = avoid is not None
        self.shape = cuda.to_device(np.asarray(grid.shape, np.int64))
        self.fixed = (
            self.shape,
            cuda.to_device(_padded_strides(grid.shape)),
            cuda.to_device(np.asarray([1.0 / h for h in grid.spacing], self.dtype)),
            scheme.order,
            cuda.to_device(kern.constants(dtype)),
            *(cuda.to_device(x) if isinstance(x, np.ndarray) else x for x in ham_args),
        )
        self.edge_sign = self.fixed[5]
        self.tstar = cuda.to_device(np.full(grid.size if record else 1, np.inf, self.dtype))
        self.tgrad = cuda.to_device(np.zeros(grid.size * grid.ndim if gradient else 0, self.dtype))
        self.monotone = monotone
        self.change_out = cuda.to_device(np.zeros(1))
        if SIMULATED:
            self.launch, self.reduce = SIMULATED_LAUNCH, (1, REDUCE_THREADS)
        else:
            self.launch = (math.ceil(grid.size / THREADS), THREADS)
            self.reduce = (min(REDUCE_BLOCKS, math.ceil(first.size / REDUCE_THREADS)), REDUCE_THREADS)

    def __enter__(self) -> GpuSolve:
        return self

    def __exit__(self, *exc) -> None:
        pass

    def mark(self) -> None:
        """Take the snapshot the next convergence check compares with."""
        self.snapshot.copy_to_device(self.buffers[0])

    def step(self, dt: float, t: float) -> int:
        """One time step from time ``t``; the node updates it made."""
        buffers = self.buffers
        u = buffers[0]
        sources = buffers[: self.stages]
        outs = (buffers[1:] + buffers[1:2])[: self.stages]
        cast = self.dtype.type
        for i, ((a, b), v, out) in enumerate(zip(self.coefficients, sources, outs)):
            final = i == self.stages - 1
            _stage[self.launch](
                v,
                u,
                out,
                cast(a),
                cast(b),
                cast(dt),
                final,
                self.monotone,
                self.target,
                self.avoid,
                self.has_avoid,
                *self.fixed,
                self.record and final,
                t,
                self.tstar,
                self.tgrad,
            )
        buffers[0], buffers[1] = buffers[1], buffers[0]
        return self.grid.size

    def change(self) -> float:
        """``max |J - snapshot|`` over the padded arrays; NaN if either holds
        a number that is not finite."""
        self.change_out.copy_to_device(np.zeros(1))
        _max_change[self.reduce](self.buffers[0], self.snapshot, self.shape, self.edge_sign, self.change_out)
        change = float(self.change_out.copy_to_host()[0])
        return change if math.isfinite(change) else math.nan

    def result(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """The value (padded), T* and its gradient (None if not recorded), on the host."""
        value = self.buffers[0].copy_to_host()
        tstar = self.tstar.copy_to_host() if self.record else None
        tgrad = self.tgrad.copy_to_host() if self.with_gradient else None
        self.buffers = []
        return value, tstar, tgrad


def _copy(array):
    """A device copy of a device array."""
    out = cuda.device_array_like(array)
    out.copy_to_device(array)
    return out


def check_memory(need: int, name: str, grid) -> None:
    """Refuse a solve whose arrays would not fit in the GPU's free memory."""
    free = free_bytes()
    if need > free:
        dims = "x".join(str(n) for n in grid.shape)
        raise InputError(
            f"grid {dims} ({grid.size:,} nodes) needs about {need / 1e9:.2f} GB on {name} "
            f"but only {free / 1e9:.2f} GB of its memory is free"
        )
