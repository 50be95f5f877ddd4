"""Compiled kernels of the level-set solver in ``solvers.levelset.hji``.

Every function the stage kernel calls lives in this one module because numba
invalidates an on-disk cache entry only when the file holding the cached
function changes: a derivative scheme kept in another file could change
without the cached stage kernel noticing.

Value-sized arrays are stored padded: three ghost nodes on each side of the
last two axes, so that a plane (all nodes sharing the indices of the outer
axes) is one contiguous block of ``(na + 6) * (nb + 6)`` values whose
neighbours along either plane axis are fixed offsets away. For each plane
the kernel builds one-sided derivatives along every axis, the numerical
Hamiltonian and the Runge-Kutta combination in a few straight loops over the
plane's rows taken as one run (ghost columns included and overwritten
afterwards), so the loops are long and vectorise, and only plane-sized
scratch exists besides the value buffers. Neighbour planes along the outer
axes are read in place; only planes beyond the grid edge are made up.

The stage kernel works on blocks of whole rows (``_block_layout``): whole
planes for the full-grid solve, runs of rows for the local one (the narrow
band around the front, ``front_rows``, ``row_blocks``), with the same
arithmetic node for node.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types

# No nnan/ninf: infinities are meaningful (T* of nodes never reached).
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

WENO_EPS = 1e-6  # the smoothness-indicator offset of hj_reachability and ToolboxLS

SIMPLE_MOTION = 0
CONTROL_AFFINE = 1

NO_INPUT = 0
BOX = 1
BALL = 2

DYNAMICS_SIGNATURE = types.void(types.float64[::1], types.float64[::1], types.float64[:, ::1], types.float64[:, ::1])


def constants(dtype) -> np.ndarray:
    """The numbers the kernels use, in the value dtype: a float literal in
    the loops would turn float32 arithmetic into float64 and halve the
    vector width."""
    return np.array(
        [13 / 12, 1 / 4, 2, 3, 4, WENO_EPS, 0.1, 0.6, 0.3, 1 / 3, 1 / 6, 7 / 6, 11 / 6, 5 / 6, 0.5, 0], dtype=dtype
    )


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _weno5(d0, d1, d2, d3, d4, c):
    """Jiang-Peng WENO5 derivative from five consecutive divided differences,
    upwind end first (Osher & Fedkiw, eqs. 3.28-3.39); ``c`` is ``constants``."""
    c1312, c14, two, three, four, eps, w1, w2, w3, third, sixth, c76, c116, c56 = c
    t, r = d0 - two * d1 + d2, d0 - four * d1 + three * d2
    s1 = c1312 * t * t + c14 * r * r + eps
    t, r = d1 - two * d2 + d3, d1 - d3
    s2 = c1312 * t * t + c14 * r * r + eps
    t, r = d2 - two * d3 + d4, three * d2 - four * d3 + d4
    s3 = c1312 * t * t + c14 * r * r + eps
    a1 = w1 / (s1 * s1)
    a2 = w2 / (s2 * s2)
    a3 = w3 / (s3 * s3)
    p1 = d0 * third - c76 * d1 + c116 * d2
    p2 = c56 * d2 - d1 * sixth + d3 * third
    p3 = d2 * third + c56 * d3 - d4 * sixth
    return (a1 * p1 + a2 * p2 + a3 * p3) / (a1 + a2 + a3)


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _derivatives(r0, r1, r2, r3, r4, r5, r6, inv_dx, order, k, left, right, n):
    """Left and right derivatives along one axis for the first ``n`` nodes
    of a run; ``r3`` is the run itself and ``r0``..``r6`` its neighbours at
    offsets -3..3 along the axis (first order reads only ``r2``..``r4``)."""
    if order == 1:
        for j in range(n):
            left[j] = (r3[j] - r2[j]) * inv_dx
            right[j] = (r4[j] - r3[j]) * inv_dx
        return
    c = (k[0], k[1], k[2], k[3], k[4], k[5], k[6], k[7], k[8], k[9], k[10], k[11], k[12], k[13])
    for j in range(n):
        d0 = (r1[j] - r0[j]) * inv_dx
        d1 = (r2[j] - r1[j]) * inv_dx
        d2 = (r3[j] - r2[j]) * inv_dx
        d3 = (r4[j] - r3[j]) * inv_dx
        d4 = (r5[j] - r4[j]) * inv_dx
        d5 = (r6[j] - r5[j]) * inv_dx
        left[j] = _weno5(d0, d1, d2, d3, d4, c)
        right[j] = _weno5(d5, d4, d3, d2, d1, c)


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _beyond(edge, inner, distance, sign):
    """The value ``distance`` nodes beyond a grid edge: the edge value moved
    by the edge slope's magnitude, upwards (``sign`` +1) or downwards (-1),
    so that whoever the ``sign`` works against never gains by leaving the
    grid (see ``solvers.levelset.hji``)."""
    return edge + sign * abs(edge - inner) * distance


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _ghost(edge, inner, distance, sign, out):
    for j in range(edge.shape[0]):
        out[j] = _beyond(edge[j], inner[j], distance, sign)


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _neighbour(v, base, n, i, o, size, stride, w, sign, scratch):
    """The plane ``o`` nodes away along an outer axis from the plane at
    ``base`` (``n`` values), whose index along that axis is ``i`` of
    ``size``; beyond the edge it is made up in ``scratch``. Offsets beyond
    the stencil half-width ``w`` are unused and give the plane itself."""
    if o > w or o < -w:
        o = 0
    j = i + o
    if j < 0:
        e = base - i * stride
        _ghost(v[e : e + n], v[e + stride : e + stride + n], -j, sign, scratch)
        return scratch
    if j >= size:
        e = base + (size - 1 - i) * stride
        _ghost(v[e : e + n], v[e - stride : e - stride + n], j - size + 1, sign, scratch)
        return scratch
    return v[base + o * stride : base + o * stride + n]


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _input_extremum(c, kind, a, b, sense):
    """``sense * max over the input set of sense * c.w``: the control's
    minimum (sense -1) or the disturbance's maximum (sense +1) of ``c . w``
    over a box ``[a, b]`` or a ball of centre ``a`` and radius ``b[0]``.
    The input's dimension is ``a``'s: ``c`` may be longer (a fixed-size
    scratch array of the CUDA kernels)."""
    if kind == BOX:
        s = 0.0
        for i in range(a.shape[0]):
            s += max(sense * c[i] * a[i], sense * c[i] * b[i])
        return sense * s
    if kind == BALL:
        s = 0.0
        norm = 0.0
        for i in range(a.shape[0]):
            s += c[i] * a[i]
            norm += c[i] * c[i]
        return s + sense * b[0] * math.sqrt(norm)
    return 0.0


@njit(cache=True)
def _input_bounds(kind, a, b, out):
    """Largest magnitude of each input component over its set."""
    for i in range(out.shape[0]):
        if kind == BOX:
            out[i] = max(abs(a[i]), abs(b[i]))
        else:
            out[i] = abs(a[i]) + b[0]


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _dissipation_coefficient(k, f0, G, K, umax, dmax):
    """A bound on ``|dH/dp_k|`` over all gradients (ToolboxLS eq. 25), as
    hj_reachability's Lax-Friedrichs schemes use for affine dynamics."""
    alpha = abs(f0[k])
    for i in range(umax.shape[0]):
        alpha += abs(G[k, i]) * umax[i]
    for i in range(dmax.shape[0]):
        alpha += abs(K[k, i]) * dmax[i]
    return alpha


@njit(cache=True)
def _plane_index(p, shape, idx):
    """Grid indices of plane ``p`` along the outer axes."""
    for k in range(shape.shape[0] - 3, -1, -1):
        idx[k] = p % shape[k]
        p //= shape[k]


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _fill_ghosts(arr, start, na, nb, sign_a, sign_b):
    """Ghost columns of every row, then ghost rows, of the padded plane
    beginning at ``start``; ``sign_a`` and ``sign_b`` are the edge signs of
    the plane's two axes."""
    W = nb + 6
    for i in range(na):
        r = start + (3 + i) * W + 3
        for m in range(1, 4):
            arr[r - m] = _beyond(arr[r], arr[r + 1], m, sign_b)
            arr[r + nb - 1 + m] = _beyond(arr[r + nb - 1], arr[r + nb - 2], m, sign_b)
    first = start + 3 * W
    last = start + (2 + na) * W
    for m in range(1, 4):
        _ghost(
            arr[first : first + W], arr[first + W : first + 2 * W], m, sign_a, arr[first - m * W : first - (m - 1) * W]
        )
        _ghost(arr[last : last + W], arr[last - W : last], m, sign_a, arr[last + m * W : last + (m + 1) * W])


@njit(cache=True)
def fill_ghosts(arr, shape, edge_sign):
    """Ghost nodes of every plane of a padded array."""
    na, nb = shape[-2], shape[-1]
    plane = (na + 6) * (nb + 6)
    for p in range(arr.shape[0] // plane):
        _fill_ghosts(arr, p * plane, na, nb, edge_sign[-2], edge_sign[-1])


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _affine_block(node0, rows, nb, pl, pr, f0s, Gs, Ks, alphas, u_kind, u_a, u_b, d_kind, d_a, d_b, p, cu, cd, dv):
    """Lax-Friedrichs Hamiltonian of control-affine dynamics over a block
    (``_block_layout``) whose first node is ``node0``."""
    W = nb + 6
    for i in range(rows):
        for jj in range(nb):
            j = i * W + 3 + jj
            dv[j] = _affine_hamiltonian(
                pl, pr, j, node0 + i * nb + jj, f0s, Gs, Ks, alphas, u_kind, u_a, u_b, d_kind, d_a, d_b, p, cu, cd
            )


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _affine_hamiltonian(pl, pr, j, node, f0s, Gs, Ks, alphas, u_kind, u_a, u_b, d_kind, d_a, d_b, p, cu, cd):
    """The Lax-Friedrichs Hamiltonian of control-affine dynamics at grid node
    ``node`` (in C order), from its left and right derivatives ``pl[k, j]``
    and ``pr[k, j]``, the tabulated ``f0``, ``G``, ``K`` and dissipation
    coefficients (``tabulate``) and scratch ``p``, ``cu`` and ``cd`` (at least
    as long as the state, the control and the disturbance). The CPU stage and
    the CUDA kernels (``solvers.levelset.cuda``) both call it."""
    ndim = f0s.shape[1]
    h = 0.0
    diss = 0.0
    for k in range(ndim):
        p[k] = 0.5 * (pl[k, j] + pr[k, j])
        h += p[k] * f0s[node, k]
        diss += alphas[node, k] * (pr[k, j] - pl[k, j])
    for i_u in range(Gs.shape[2]):
        s = 0.0
        for k in range(ndim):
            s += Gs[node, k, i_u] * p[k]
        cu[i_u] = s
    for i_d in range(Ks.shape[2]):
        s = 0.0
        for k in range(ndim):
            s += Ks[node, k, i_d] * p[k]
        cd[i_d] = s
    h += _input_extremum(cu, u_kind, u_a, u_b, -1.0) + _input_extremum(cd, d_kind, d_a, d_b, 1.0)
    return h + 0.5 * diss


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _simple_motion_block(
    idx,
    row0,
    rows,
    nb,
    n,
    pl,
    pr,
    half,
    axis_player,
    player_sign,
    speed,
    speed_offset,
    speed_stride,
    spd,
    norm,
    dv,
):
    """Lax-Friedrichs Hamiltonian ``sum_q sign_q v_q |p_q|`` over the first
    ``n`` entries of a block's run (``_block_layout``), with each axis's
    dissipation coefficient the local speed of its player."""
    ndim = axis_player.shape[0]
    ka, kb = ndim - 2, ndim - 1
    for q in range(player_sign.shape[0]):
        base = speed_offset[q]
        for k in range(ka):
            base += idx[k] * speed_stride[q, k]
        sa, sb = speed_stride[q, ka], speed_stride[q, kb]
        for i in range(rows):
            row = spd[q, i * (nb + 6) + 3 : i * (nb + 6) + 3 + nb]
            for jj in range(nb):
                row[jj] = speed[base + (row0 + i) * sa + jj * sb]
        for j in range(n):
            norm[q, j] = 0
    for j in range(n):
        dv[j] = 0
    for k in range(ndim):
        q = axis_player[k]
        if q < 0:
            continue
        for j in range(n):
            c = half * (pl[k, j] + pr[k, j])
            norm[q, j] += c * c
            dv[j] += half * spd[q, j] * (pr[k, j] - pl[k, j])
    for q in range(player_sign.shape[0]):
        s = player_sign[q]
        for j in range(n):
            dv[j] += s * spd[q, j] * np.sqrt(norm[q, j])


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def _stencil(v, base, n, k, idx, shape, w, sign, ghosts):
    """The seven runs at offsets -3..3 along axis ``k`` around the run of
    plane rows at ``base``: in place along the plane axes (ghosts are
    stored), in place or made up in ``ghosts`` along the outer axes."""
    ndim = shape.shape[0]
    na, nb = shape[ndim - 2], shape[ndim - 1]
    if k >= ndim - 2:
        st = nb + 6 if k == ndim - 2 else 1
        return (
            v[base - 3 * st : base - 3 * st + n],
            v[base - 2 * st : base - 2 * st + n],
            v[base - st : base - st + n],
            v[base : base + n],
            v[base + st : base + st + n],
            v[base + 2 * st : base + 2 * st + n],
            v[base + 3 * st : base + 3 * st + n],
        )
    st = (na + 6) * (nb + 6)
    for j in range(k + 1, ndim - 2):
        st *= shape[j]
    i, size = idx[k], shape[k]
    return (
        _neighbour(v, base, n, i, -3, size, st, w, sign, ghosts[0]),
        _neighbour(v, base, n, i, -2, size, st, w, sign, ghosts[1]),
        _neighbour(v, base, n, i, -1, size, st, w, sign, ghosts[2]),
        v[base : base + n],
        _neighbour(v, base, n, i, 1, size, st, w, sign, ghosts[4]),
        _neighbour(v, base, n, i, 2, size, st, w, sign, ghosts[5]),
        _neighbour(v, base, n, i, 3, size, st, w, sign, ghosts[6]),
    )


@njit(cache=True, nogil=True, fastmath=_FASTMATH, error_model="numpy")
def stage(
    first,
    stop,
    blocks,
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
    """One Runge-Kutta stage in Shu-Osher form on blocks ``first`` to
    ``stop - 1`` of ``blocks`` (``_block_layout``) of padded arrays:
    ``out = a u0 + b (v + dt L(v))`` with ``L`` the Lax-Friedrichs
    numerical Hamiltonian of backward time, ghosts of ``out`` refreshed on
    every plane once its last block is done (a thread's blocks end at a
    plane's end). The last stage of a step (``final``) also keeps
    ``out <= u0`` if ``monotone``, applies the reach-avoid clamp
    ``max(min(out, target), -avoid)`` and, if
    ``record``, stamps T* and the gradient (unpadded arrays) on nodes
    entering the set. It releases the GIL so that threads can share the
    planes: numba's own parallel loops would double the cold compile time."""
    ndim = shape.shape[0]
    na, nb = shape[ndim - 2], shape[ndim - 1]
    W = nb + 6
    n = na * W  # the run of real rows, ghost columns included
    w = 1 if order == 1 else 3
    m, q, nplayers = u_a.shape[0], d_a.shape[0], player_sign.shape[0]
    idx = np.zeros(ndim, np.int64)
    ghosts = np.empty((7, n), v.dtype)
    pl = np.empty((ndim, n), v.dtype)
    pr = np.empty((ndim, n), v.dtype)
    dv = np.empty(n, v.dtype)
    spd = np.zeros((nplayers, n), v.dtype)
    norm = np.empty((nplayers, n), v.dtype)
    p = np.empty(ndim)
    cu, cd = np.empty(m), np.empty(q)
    for bi in range(first, stop):
        pi, row0, rows = blocks[bi, 0], blocks[bi, 1], blocks[bi, 2]
        start = pi * (na + 6) * W
        base, n = _block_layout(start, row0, rows, nb)
        node0 = (pi * na + row0) * nb
        _plane_index(pi, shape, idx)
        for k in range(ndim):
            r0, r1, r2, r3, r4, r5, r6 = _stencil(v, base, n, k, idx, shape, w, edge_sign[k], ghosts)
            _derivatives(r0, r1, r2, r3, r4, r5, r6, inv_dx[k], order, consts, pl[k], pr[k], n)
        if kind == SIMPLE_MOTION:
            _simple_motion_block(
                idx,
                row0,
                rows,
                nb,
                n,
                pl,
                pr,
                consts[14],
                axis_player,
                player_sign,
                speed,
                speed_offset,
                speed_stride,
                spd,
                norm,
                dv,
            )
        else:
            _affine_block(
                node0,
                rows,
                nb,
                pl,
                pr,
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
                p,
                cu,
                cd,
                dv,
            )
        centre = v[base : base + n]
        o_run = out[base : base + n]
        u_run = u0[base : base + n]
        for j in range(n):
            o_run[j] = a * u_run[j] + b * (centre[j] + dt * dv[j])
        if final:
            if monotone:
                for j in range(n):
                    o_run[j] = min(o_run[j], u_run[j])
            t_run = target[base : base + n]
            for j in range(n):
                o_run[j] = min(o_run[j], t_run[j])
            if has_avoid:
                g_run = avoid[base : base + n]
                for j in range(n):
                    o_run[j] = max(o_run[j], -g_run[j])
            if record:
                _record(o_run, u_run, pl, pr, rows, nb, node0, t_old, dt, tstar, tgrad)
        if bi == stop - 1 or blocks[bi + 1, 0] != pi:
            _fill_ghosts(out, start, na, nb, edge_sign[ndim - 2], edge_sign[ndim - 1])


@njit(cache=True)
def _block_layout(start, row0, rows, nb):
    """Where rows ``row0`` to ``row0 + rows - 1`` of the plane at ``start``
    lie in a padded array: ``(base, n)``, their run ``[base, base + n)``,
    node ``(i, jj)`` of the block at ``base + i * (nb + 6) + 3 + jj``. The
    block is read as one run across its rows, ghost columns included: the
    long loops vectorise, and ``_fill_ghosts`` overwrites the ghost
    entries."""
    W = nb + 6
    return start + (3 + row0) * W, rows * W


def plane_blocks(shape) -> np.ndarray:
    """One block per plane, each its whole plane: the full-grid solve."""
    na = shape[-2]
    planes = int(np.prod(shape[:-2]))
    blocks = np.zeros((planes, 3), np.int64)
    blocks[:, 0] = np.arange(planes)
    blocks[:, 2] = na
    return blocks


@njit(cache=True)
def _record(o_run, u_run, pl, pr, rows, nb, node0, t_old, dt, tstar, tgrad):
    """T* and the central gradient of the nodes of one block that entered
    the set during this step; the entry time is interpolated linearly."""
    ndim = pl.shape[0]
    W = nb + 6
    for i in range(rows):
        for jj in range(nb):
            j = i * W + 3 + jj
            node = node0 + i * nb + jj
            after = o_run[j]
            if after <= 0 and tstar[node] == np.inf:
                tstar[node] = _entry_time(u_run[j], after, t_old, dt)
                if tgrad.shape[0] == 0:
                    continue
                for k in range(ndim):
                    tgrad[node * ndim + k] = 0.5 * (pl[k, j] + pr[k, j])


@njit(cache=True)
def _entry_time(before, after, t_old, dt):
    """When a node whose value went from ``before`` to ``after <= 0`` over
    the step from ``t_old`` to ``t_old + dt`` entered the set, interpolated
    linearly (``t_old`` if it was in already)."""
    frac = before / (before - after) if before > 0 else 0.0
    return t_old + frac * dt


@njit(cache=True)
def max_abs_difference(a, b):
    """``max |a - b|`` over two flat arrays; NaN as soon as either holds a
    number that is not finite, which ``max`` would otherwise pass over."""
    mx = 0.0
    for i in range(a.shape[0]):
        d = abs(np.float64(a[i]) - np.float64(b[i]))
        if not d < np.inf:
            return np.nan
        mx = max(mx, d)
    return mx


@njit(cache=True)
def tabulate(shape, lo, dx, dyn, u_kind, u_a, u_b, d_kind, d_a, d_b, f0s, Gs, Ks, alphas):
    """``f0``, ``G`` and ``K`` of time-invariant control-affine dynamics at
    every node (in C order), and each node's dissipation coefficients: the
    stage kernel then reads them instead of calling the dynamics, which it
    could reach only through a function pointer, at every node of every
    stage. Returns ``max over nodes of sum_k alpha_k / dx_k``, the rate that
    bounds the CFL time step, or NaN if the dynamics gave a non-finite number."""
    ndim = shape.shape[0]
    m = u_a.shape[0]
    q = d_a.shape[0]
    x = np.empty(ndim)
    f0 = np.empty(ndim)
    G = np.empty((ndim, m))
    K = np.empty((ndim, q))
    umax = np.empty(m)
    dmax = np.empty(q)
    _input_bounds(u_kind, u_a, u_b, umax)
    _input_bounds(d_kind, d_a, d_b, dmax)
    best = 0.0
    for flat in range(f0s.shape[0]):
        rest = flat
        for k in range(ndim - 1, -1, -1):
            x[k] = lo[k] + (rest % shape[k]) * dx[k]
            rest //= shape[k]
        dyn(x, f0, G, K)
        rate = 0.0
        for k in range(ndim):
            alpha = _dissipation_coefficient(k, f0, G, K, umax, dmax)
            if not np.isfinite(alpha):
                return np.nan
            rate += alpha / dx[k]
            f0s[flat, k] = f0[k]
            alphas[flat, k] = alpha
            for i in range(m):
                Gs[flat, k, i] = G[k, i]
            for i in range(q):
                Ks[flat, k, i] = K[k, i]
        best = max(best, rate)
    return best


@njit(cache=True, nogil=True)
def _crossing(v, a, b, n):
    """Whether nodes ``a + j`` and ``b + j`` lie on either side of the zero
    level for some ``j < n``; a branch-free count, so the loop vectorises."""
    crossings = 0
    for j in range(n):
        crossings += (v[a + j] <= 0) != (v[b + j] <= 0)
    return crossings > 0


@njit(cache=True, nogil=True)
def front_rows(first, stop, v, shape, band, rows):
    """Mark in ``rows`` (one byte per row of the grid, ``shape[:-1]``
    flattened) every row holding two neighbours along its own axis on
    either side of the zero level, and both rows of every pair of
    neighbouring rows that hold such neighbours across them; rows of
    ``band`` (the same layout) only, where the front can be, and planes
    ``first`` to ``stop - 1`` only, without the GIL, so that threads can
    share the planes."""
    ndim = shape.shape[0]
    na, nb = shape[ndim - 2], shape[ndim - 1]
    W = nb + 6
    plane = (na + 6) * W
    strides = np.empty(ndim - 1, np.int64)  # padded offset of one step along each axis but the last
    steps = np.empty(ndim - 1, np.int64)  # row-index offset of the same step
    strides[ndim - 2], steps[ndim - 2] = W, 1
    s, t = plane, na
    for k in range(ndim - 3, -1, -1):
        strides[k], steps[k] = s, t
        s *= shape[k]
        t *= shape[k]
    idx = np.zeros(ndim, np.int64)
    for p in range(first, stop):
        _plane_index(p, shape, idx)
        for i in range(na):
            idx[ndim - 2] = i
            row = p * na + i
            if band[row] == 0:
                continue
            at = p * plane + (3 + i) * W + 3
            if _crossing(v, at, at + 1, nb - 1):
                rows[row] = 1
            for k in range(ndim - 1):
                if idx[k] + 1 < shape[k] and _crossing(v, at, at + strides[k], nb):
                    rows[row] = 1
                    rows[row + steps[k]] = 1


@njit(cache=True)
def row_blocks(rows, shape):
    """The rows marked in ``rows`` as stage blocks (``_block_layout``),
    consecutive marked rows of a plane merged into one block so that the
    loops run long."""
    na = shape[shape.shape[0] - 2]
    out = np.empty((rows.shape[0], 3), np.int64)
    n = 0
    for p in range(rows.shape[0] // na):
        i = 0
        while i < na:
            if rows[p * na + i] == 0:
                i += 1
                continue
            a = i
            while i < na and rows[p * na + i] != 0:
                i += 1
            out[n, 0], out[n, 1], out[n, 2] = p, a, i - a
            n += 1
    return out[:n].copy()


@njit(cache=True, nogil=True)
def copy_rows(first, stop, src, dst, rows, shape):
    """Copy from ``src`` to ``dst`` (padded arrays) the rows marked in
    ``rows`` (as in ``front_rows``) of planes ``first`` to ``stop - 1``,
    each with its ghost columns, and the ghost rows beside a plane's edge
    rows, which are made from them."""
    ndim = shape.shape[0]
    na, nb = shape[ndim - 2], shape[ndim - 1]
    W = nb + 6
    plane = (na + 6) * W
    for p in range(first, stop):
        for i in range(na):
            if rows[p * na + i] == 0:
                continue
            lo = 0 if i == 0 else 3 + i
            hi = na + 6 if i == na - 1 else 4 + i
            a, b = p * plane + lo * W, p * plane + hi * W
            dst[a:b] = src[a:b]
