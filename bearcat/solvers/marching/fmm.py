"""Fast marching for the eikonal equation ``v(y) |grad phi(y)| = 1`` on a 2-D grid.

One marching kernel serves two jobs. Plain fast marching gives minimum travel
times (a defender's ``psi``). With a per-node ``ceiling`` it is the modified
method of thesis 4.1.3: a node whose value, when it is accepted, is not below
its ceiling (the defenders' time-to-capture) is set to infinity and stops the
front there, so the finite nodes are exactly the safe-reachable set.
Optimal paths run down the result (``solvers.marching.descent``).

Arrays are indexed ``[ix, iy]`` (x east, y north); ``spacing`` is ``h`` or
``(hx, hy)`` in metres, speeds are metres per second, values are seconds.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from bearcat.solvers.errors import InputError, format_point, non_negative
from bearcat.solvers.grid import Grid

__all__ = ["march", "point_source", "source_stencil", "time_to_capture", "travel_time"]

_FAR = -1  # node states in the queue-slot array
_DONE = -2
_HEAP = -3  # a slot of _HEAP - i: heap entry i
_PAD = 2  # second-order differences look two nodes away; the border is blocked.
_BUCKETS_PER_STEP = 64.0  # ring buckets per one-node step at the top speed
_BUCKET_SIZE = 64
_MAX_BUCKETS = 1 << 14


def travel_time(speed, spacing, initial, *, order: int = 1, ceiling=None) -> np.ndarray:
    """Arrival times of the front started from ``initial``.

    ``speed`` >= 0 per node; a node of speed 0 is impassable and stays at
    infinity. ``initial`` holds finite values at source nodes and infinity
    elsewhere. Sources join the narrow band with their values rather than being
    accepted outright, so a source a cheaper neighbour can reach sooner is
    improved: stage ``k`` of a multi-stage game is seeded with ``phi_{k-1}``
    along a whole target set, where only the cheapest entries are binding.

    ``ceiling`` (same shape, seconds) makes this the modified fast marching
    method: a node accepted with a value at or above its ceiling gets infinity
    and does not spread.

    ``order=2`` uses second-order upwind differences on each axis whose two
    upwind nodes are accepted and decrease monotonically away from the node,
    and first order elsewhere (the scheme of scikit-fmm). It is second-order
    accurate where the solution is smooth and the speed is smooth along the
    stencil; it keeps first-order accuracy at point sources (seed a
    neighbourhood of exact values to recover more), at shocks behind
    obstacles and across speed discontinuities.
    """
    speed, hx, hy, initial = _check_march_inputs(speed, spacing, initial)
    if order not in (1, 2):
        raise InputError(f"order must be 1 or 2, got {order!r}")
    if ceiling is not None:
        ceiling = np.asarray(ceiling, dtype=np.float64)
        if ceiling.shape != speed.shape:
            raise InputError(f"ceiling has shape {ceiling.shape} but speed has shape {speed.shape}")
        if np.isnan(ceiling).any():
            raise InputError("ceiling has a NaN value")
    return march(speed, hx, hy, initial, ceiling, order)


def march(speed, hx: float, hy: float, initial, ceiling=None, order: int = 1) -> np.ndarray:
    """``travel_time`` for callers that have already validated their inputs."""
    return _march(
        np.ascontiguousarray(speed, dtype=np.float64),
        float(hx),
        float(hy),
        np.ascontiguousarray(initial, dtype=np.float64),
        _NO_CEILING if ceiling is None else np.ascontiguousarray(ceiling, dtype=np.float64),
        np.int64(order),
    )


_NO_CEILING = np.empty((0, 0))


def point_source(grid: Grid, point, speed) -> np.ndarray:
    """Initial values for a front leaving ``point`` at time 0.

    The nodes of the cell holding ``point``, and any other node within one
    spacing of it, get their exact Euclidean distance divided by the speed at
    that node; the rest is infinity. Seeding exact times instead of snapping
    the source to a node keeps the solution free of a half-cell offset.
    """
    speed = np.asarray(speed, dtype=np.float64)
    if speed.shape != grid.shape:
        raise InputError(f"speed has shape {speed.shape} but the grid has shape {grid.shape}")
    ix, iy, dist = source_stencil(grid, point)
    v = speed[ix, iy]
    initial = np.full(grid.shape, np.inf)
    passable = v > 0
    if not passable.any():
        x, y = (float(c) for c in point)
        raise InputError(f"point ({x:g}, {y:g}) has no passable grid node within one spacing")
    initial[ix[passable], iy[passable]] = dist[passable] / v[passable]
    return initial


def time_to_capture(psi, spacing, radius: float) -> np.ndarray:
    """Time for a pursuer with arrival times ``psi`` to come within ``radius``.

    ``psi^c(y) = min psi(x)`` over nodes ``x`` with ``|x - y| <= radius`` (the
    capture mask of thesis 4.1.3), a min-filter over a Euclidean disk. Unlike
    ``psi - radius / v`` it stays right across obstacles and speed changes:
    the pursuer need only reach some node of the disk. Radius 0 is capture
    on contact: ``psi`` unchanged.
    """
    psi = np.asarray(psi, dtype=np.float64)
    hx, hy = _spacing(spacing)
    radius = non_negative(radius, "capture radius")
    if radius == 0:
        return psi
    return _disk_min(np.ascontiguousarray(psi), disk_widths(radius, hx, hy))


def disk_widths(radius: float, hx: float, hy: float) -> np.ndarray:
    """The capture disk as chords along y, one per x offset ``i``: the node
    offsets ``(i, j)`` with ``|j| <= widths[|i|]``. ``time_to_capture`` takes
    a running minimum along each row per distinct chord length, then a
    minimum over x offsets, so its cost grows with the radius in cells, not
    the disk's area."""
    if radius == 0:
        return np.zeros(1, dtype=np.int64)
    reach = radius * (1 + 1e-12)
    return np.array(
        [int(math.sqrt(max(reach**2 - (i * hx) ** 2, 0.0)) // hy) for i in range(int(reach // hx) + 1)],
        dtype=np.int64,
    )


# --------------------------------------------------------------------------- helpers


def _spacing(spacing) -> tuple[float, float]:
    h = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (2,))
    if not np.all(np.isfinite(h) & (h > 0)):
        raise InputError(f"spacing must be positive and finite, got {spacing!r}")
    return float(h[0]), float(h[1])


def _check_march_inputs(speed, spacing, initial):
    speed = np.asarray(speed, dtype=np.float64)
    initial = np.asarray(initial, dtype=np.float64)
    if speed.ndim != 2:
        raise InputError(f"speed must be a 2-D array, got {speed.ndim} dimensions")
    if min(speed.shape) < 2:
        raise InputError(f"speed must have at least two nodes per axis, got shape {speed.shape}")
    if initial.shape != speed.shape:
        raise InputError(f"initial has shape {initial.shape} but speed has shape {speed.shape}")
    if not (np.isfinite(speed) & (speed >= 0)).all():
        raise InputError("speed has a negative, NaN or infinite value")
    if np.isnan(initial).any() or (initial == -np.inf).any():
        raise InputError("initial has a NaN or -inf value")
    hx, hy = _spacing(spacing)
    return speed, hx, hy, initial


def source_stencil(grid: Grid, point):
    """Nodes seeded for a source at ``point`` and their distances to it."""
    p = np.asarray(point, dtype=np.float64)
    if p.shape != (2,) or not grid.contains(p):
        raise InputError(f"point {format_point(point)} lies outside the grid")
    fi = grid.fractional_index(p)
    shape = np.asarray(grid.shape)
    cell = np.clip(np.floor(fi).astype(np.int64), 0, shape - 2)
    ax = [np.arange(max(c - 1, 0), min(c + 3, n)) for c, n in zip(cell, shape)]
    ix, iy = (a.ravel() for a in np.meshgrid(*ax, indexing="ij"))
    h = np.asarray(grid.spacing)
    dist = np.hypot((ix - fi[0]) * h[0], (iy - fi[1]) * h[1])
    corner = (ix >= cell[0]) & (ix <= cell[0] + 1) & (iy >= cell[1]) & (iy <= cell[1] + 1)
    keep = corner | (dist <= h.max() * (1 + 1e-12))
    return ix[keep], iy[keep], dist[keep]


# --------------------------------------------------------------------------- kernels


@numba.njit(cache=True, nogil=True)
def _march(speed, hx, hy, initial, ceiling, order):
    nx, ny = speed.shape
    sy = ny + 2 * _PAD  # flat stride of x in the padded layout
    size = (nx + 2 * _PAD) * sy
    # Per node: its slot in the queue (>= 0 a ring slot, <= _HEAP a heap
    # slot), or _FAR / _DONE; the border and obstacles start done.
    where = np.full(size, _DONE, dtype=np.int32)
    acc = np.full(size, np.inf)  # accepted values; infinity until accepted
    slow = np.empty(size)  # 1 / speed
    capped = ceiling.size > 0  # an empty ceiling array: plain fast marching
    ceil = np.empty(size if capped else 0)
    second = order == 2
    # Second-order differences can undershoot next to a kink, such as the one a
    # point source puts in its seeds; a seed is only lowered by a first-order
    # (monotone) update, which never undershoots.
    seeded = np.zeros(size if second else 0, dtype=np.bool_)
    hval = np.empty(nx * ny)
    hidx = np.empty(nx * ny, dtype=np.int32)
    n = 0
    fmin = np.inf
    fmax = 0.0
    for ix in range(nx):
        base = (ix + _PAD) * sy + _PAD
        for iy in range(ny):
            k = base + iy
            v = speed[ix, iy]
            if v > 0:
                where[k] = _FAR
                f = 1.0 / v
                slow[k] = f
                fmin = min(fmin, f)
                fmax = max(fmax, f)
                if capped:
                    ceil[k] = ceiling[ix, iy]
                t = initial[ix, iy]
                if t < np.inf:
                    _sift_up(hval, hidx, where, n, t, k)
                    n += 1
                    if second:
                        seeded[k] = True
    # The queue is exact, in two parts. A new value lies less than h f_max
    # after the value just accepted, so a ring of buckets of width ``width``
    # covering that span takes it in O(1); the least value is the least of
    # the first non-empty bucket. Anything else (seeds, a full bucket, a
    # value beyond the ring) goes to the 4-ary heap, and each pop takes the
    # lesser of the two heads.
    width = min(hx, hy) * fmin / _BUCKETS_PER_STEP
    span = max(hx, hy) * fmax
    buckets = 1
    while buckets < span / width + 2 and buckets < _MAX_BUCKETS:
        buckets *= 2
    width = max(width, span / (buckets - 2))
    inv_width = 1.0 / width
    mask = buckets - 1
    bval = np.empty(buckets * _BUCKET_SIZE)
    bidx = np.empty(buckets * _BUCKET_SIZE, dtype=np.int32)
    bcount = np.zeros(buckets, dtype=np.int32)

    # Closures, not helper functions: numba inlines them without the
    # reference counting of array arguments, a third of the run time here.
    def bucket_of(t):
        # Clamping keeps the order and any float within int64.
        return math.floor(max(min(t * inv_width, 1e18), -1e18))

    def remove(slot):
        b = slot // _BUCKET_SIZE
        last = b * _BUCKET_SIZE + bcount[b] - 1
        if slot != last:
            bval[slot] = bval[last]
            q = bidx[last]
            bidx[slot] = q
            where[q] = slot
        bcount[b] -= 1

    in_ring = 0
    first = bucket_of(hval[0]) if n > 0 else 0  # the first bucket that may hold entries
    while n > 0 or in_ring > 0:
        top = hval[0] if n > 0 else np.inf
        from_heap = True
        if in_ring > 0:
            stop = bucket_of(top)
            while bcount[first & mask] == 0 and first < stop:
                first += 1
            b = first & mask
            c = bcount[b]
            if c > 0:
                lo = b * _BUCKET_SIZE
                m = lo
                t = bval[lo]
                for q in range(lo + 1, lo + c):
                    vq = bval[q]
                    m = q if vq < t else m
                    t = min(vq, t)
                if t <= top:
                    from_heap = False
                    k = bidx[m]
                    remove(m)
                    in_ring -= 1
        if from_heap:
            t = top
            k = hidx[0]
            n = _pop(hval, hidx, where, n)
            if in_ring == 0:
                first = max(first, bucket_of(t))
        where[k] = _DONE
        if capped and t >= ceil[k]:
            continue  # step 4.5: reachable only after capture, so not safe-reachable
        acc[k] = t
        for d in range(4):
            if d == 0:
                j = k - sy
            elif d == 1:
                j = k + sy
            elif d == 2:
                j = k - 1
            else:
                j = k + 1
            slot = where[j]
            if slot == _DONE:
                continue
            u = _update(acc, j, sy, slow[j], hx, hy, second and not seeded[j])
            if slot <= _HEAP:
                if u < hval[_HEAP - slot]:
                    _sift_up(hval, hidx, where, _HEAP - slot, u, j)
                continue
            if slot >= 0:
                if u >= bval[slot]:
                    continue
                remove(slot)
                in_ring -= 1
            a = max(bucket_of(u), first)
            b = a & mask
            if a - first < buckets and bcount[b] < _BUCKET_SIZE:
                q = b * _BUCKET_SIZE + bcount[b]
                bval[q] = u
                bidx[q] = j
                where[j] = q
                bcount[b] += 1
                in_ring += 1
            else:
                _sift_up(hval, hidx, where, n, u, j)
                n += 1
    # Unpad in place: every row moves towards the front, so a forward copy is
    # safe, and the result needs no second grid-sized allocation.
    for ix in range(nx):
        base = (ix + _PAD) * sy + _PAD
        for iy in range(ny):
            acc[ix * ny + iy] = acc[base + iy]
    return acc[: nx * ny].reshape((nx, ny))


@numba.njit(cache=True, inline="always")
def _axis(acc, j, stride, h, second):
    """Upwind value along one axis and its effective step (infinite value: no term)."""
    lo = acc[j - stride]
    hi = acc[j + stride]
    if second:
        a1 = min(lo, hi)
        a2 = acc[j - 2 * stride] if lo <= hi else acc[j + 2 * stride]
        if a2 <= a1 < np.inf:
            # (phi - (4 a1 - a2) / 3) / (2h / 3) is the second-order one-sided difference.
            return (4.0 * a1 - a2) / 3.0, h * (2.0 / 3.0)
        return a1, h
    return min(lo, hi), h


@numba.njit(cache=True, inline="always")
def _update(acc, j, sy, f, hx, hy, second):
    """The upwind phi with ((phi - vx) / gx)^2 + ((phi - vy) / gy)^2 = f^2."""
    vx, gx = _axis(acc, j, sy, hx, second)
    vy, gy = _axis(acc, j, 1, hy, second)
    if vy == np.inf:
        return vx + f * gx
    if vx == np.inf:
        return vy + f * gy
    gx2 = gx * gx
    gy2 = gy * gy
    s = gx2 + gy2
    dv = vx - vy
    # The discriminant over (gx gy)^2, in a form where large times do not cancel.
    disc = s * f * f - dv * dv
    if disc >= 0.0:
        r = (gy2 * vx + gx2 * vy + gx * gy * math.sqrt(disc)) / s
        if r >= vx and r >= vy:
            return r
    return min(vx + f * gx, vy + f * gy)


@numba.njit(cache=True, inline="always")
def _sift_up(hval, hidx, where, i, t, k):
    while i > 0:
        p = (i - 1) >> 2
        pv = hval[p]
        if pv <= t:
            break
        hval[i] = pv
        q = hidx[p]
        hidx[i] = q
        where[q] = _HEAP - i
        i = p
    hval[i] = t
    hidx[i] = k
    where[k] = _HEAP - i


@numba.njit(cache=True, inline="always")
def _pop(hval, hidx, where, n):
    """Remove the root of the 4-ary heap; the caller has read it. Returns the new size."""
    n -= 1
    t = hval[n]
    k = hidx[n]
    i = 0
    while True:
        c = 4 * i + 1
        if c + 3 < n:
            # The least of four children without data-dependent branches.
            v0 = hval[c]
            v1 = hval[c + 1]
            v2 = hval[c + 2]
            v3 = hval[c + 3]
            a = c if v0 <= v1 else c + 1
            b = c + 2 if v2 <= v3 else c + 3
            va = min(v0, v1)
            vb = min(v2, v3)
            m = a if va <= vb else b
            mv = min(va, vb)
        elif c < n:
            m = c
            mv = hval[c]
            for q in range(c + 1, n):
                if hval[q] < mv:
                    mv = hval[q]
                    m = q
        else:
            break
        if mv >= t:
            break
        hval[i] = mv
        q = hidx[m]
        hidx[i] = q
        where[q] = _HEAP - i
        i = m
    if n > 0:
        hval[i] = t
        hidx[i] = k
        where[k] = _HEAP - i
    return n


@numba.njit(cache=True, nogil=True)
def _disk_min(psi, widths):
    """Minimum over the nodes ``(x + i, y + j)`` with ``|j| <= widths[|i|]``.

    Each distinct chord half-width ``w`` takes one running minimum along y
    (van Herk / Gil-Werman: blocks of ``2w + 1`` with prefix and suffix
    minima, three passes whatever ``w``), then rows ``x - i`` and ``x + i``
    fold into row ``x``.
    """
    nx, ny = psi.shape
    out = np.empty((nx, ny))
    rows = np.empty((nx, ny))
    m = ny + 4 * widths[0] + 1
    b = np.empty(m)
    g = np.empty(m)
    h = np.empty(m)
    w_done = -1
    for i in range(min(widths.size, nx)):
        w = widths[i]
        if w != w_done:
            s = 2 * w + 1
            for x in range(nx):
                for k in range(w):
                    b[k] = np.inf
                for k in range(ny):
                    b[w + k] = psi[x, k]
                for k in range(w + ny, m):
                    b[k] = np.inf
                for k0 in range(0, m - s + 1, s):
                    g[k0] = b[k0]  # minimum from the start of each block
                    for k in range(k0 + 1, k0 + s):
                        g[k] = min(g[k - 1], b[k])
                    h[k0 + s - 1] = b[k0 + s - 1]  # minimum to the end of each block
                    for k in range(k0 + s - 2, k0 - 1, -1):
                        h[k] = min(h[k + 1], b[k])
                for y in range(ny):
                    rows[x, y] = min(h[y], g[y + s - 1])
            w_done = w
        for x in range(nx):
            if i == 0:
                for y in range(ny):
                    out[x, y] = rows[x, y]
                continue
            for xs in (x - i, x + i):
                if 0 <= xs < nx:
                    for y in range(ny):
                        out[x, y] = min(out[x, y], rows[xs, y])
    return out
