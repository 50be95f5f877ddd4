"""Compiled Gauss-Seidel sweeps of the stationary game equations in
``solvers.sweeping.game``, kept in one module because numba invalidates a
cached kernel only when the file holding it changes.

A sweep visits every node once in one of the 16 orderings of a 4-D grid
(each axis forwards or backwards) and replaces its value by the solution of
the Godunov-discretised equation

    v_a |D_a u| - v_d |D_d u| = c

at that node, from its neighbours' values as they stand, so a value updated
earlier in the sweep is read at once. The Hamiltonian of simple motion is
separable, so Godunov's upwinding is exact and per axis: along an axis of
the attacker (who minimises) the smaller neighbour, along an axis of the
defender (who maximises) the larger one, and the node's value is the root
of a function that rises with it. ``c = 0`` gives the reach-avoid value
(``VALUE``), ``c = 1`` the time to win (``TIME``).

The attacker's plane is walked by anti-diagonals: two nodes of one diagonal
are never neighbours along an attacker axis, and each owns its whole
defender plane, so the columns of a diagonal run on separate threads and
read exactly what a serial sweep would; results do not depend on the number
of threads. The same holds for hyperplanes of all four axes, which is how a
GPU would take it (Detrixhe, Gibou and Min 2013).

Nodes whose neighbours did not change since their last update are skipped
(the locking of Bak, McLaughlin and Renzi 2010): after the first sweeps
only a thin layer around the settling front is still worked.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

VALUE = 0
TIME = 1

OUTSIDE = 0  # kinds of node in a TIME sweep
FIXED = 1
UPDATE = 2

_ITERATIONS = 60  # at most, of the safeguarded Newton; bisection alone would take 40 from a cell to 1e-12


@njit(cache=True, inline="always")
def _upwind(gap, inv, q, s):
    """``q`` and ``s`` with one axis's difference added where it points the
    player's way: its square to ``q``, its slope in the value to ``s``."""
    x = gap * inv
    if x > 0.0:
        return q + x * x, s + x * inv
    return q, s


@njit(cache=True, inline="always")
def _terms(u, a0, a1, b0, b1, ia0, ia1, ib0, ib1):
    """The attacker's and the defender's upwind gradient norms at value ``u``
    and their derivatives in ``u``: (A, dA, D, dD)."""
    qa, sa = _upwind(u - a0, ia0, 0.0, 0.0)
    qa, sa = _upwind(u - a1, ia1, qa, sa)
    qd, sd = _upwind(b0 - u, ib0, 0.0, 0.0)
    qd, sd = _upwind(b1 - u, ib1, qd, sd)
    A = math.sqrt(qa)
    D = math.sqrt(qd)
    dA = sa / A if A > 0.0 else 0.0
    dD = -sd / D if D > 0.0 else 0.0
    return A, dA, D, dD


@njit(cache=True, inline="always")
def _attacker_alone(a0, a1, ia0, ia1, reach):
    """The ``u`` with ``A(u) = reach`` when the defender's term is zero: the
    2-D eikonal update, in closed form."""
    if a1 < a0:
        a0, a1, ia0, ia1 = a1, a0, ia1, ia0
    u = a0 + reach / ia0
    if u <= a1:
        return u
    p = ia0 * ia0
    q = ia1 * ia1
    disc = (p + q) * reach * reach - p * q * (a1 - a0) ** 2
    return (p * a0 + q * a1 + math.sqrt(max(disc, 0.0))) / (p + q)


@njit(cache=True)
def local_root(a0, a1, b0, b1, ia0, ia1, ib0, ib1, va, vd, rhs):
    """The largest ``u`` with ``va A(u) - vd D(u) <= rhs``: the node's new
    value. ``a`` are the attacker's upwind neighbours (inf: none), ``b`` the
    defender's (-inf: none); ``ia``/``ib`` inverse spacings.

    Without the defender's term the root is the 2-D eikonal update; where
    that lies above the defender's best neighbour, the defender's term is
    zero there and it is the answer. Otherwise the root lies between it and
    that neighbour, where the function rises strictly: Newton's method,
    kept inside the bracket."""
    if not va > 0.0 or min(a0, a1) == math.inf:
        return math.inf
    lo = _attacker_alone(a0, a1, ia0, ia1, rhs / va)
    hi = max(b0, b1)
    if hi <= lo or not vd > 0.0:
        return lo
    if hi == math.inf:
        return math.inf
    # F(lo) = -vd D(lo) < 0 and F(hi) = va A(hi) - rhs > 0.
    u = hi
    for _ in range(_ITERATIONS):
        A, dA, D, dD = _terms(u, a0, a1, b0, b1, ia0, ia1, ib0, ib1)
        f = va * A - vd * D - rhs
        if f > 0.0:
            hi = u
        else:
            lo = u
        slope = va * dA - vd * dD
        nxt = u - f / slope if slope > 0.0 else 0.5 * (lo + hi)
        if not (lo < nxt < hi):
            nxt = 0.5 * (lo + hi)
        if abs(nxt - u) <= 1e-12 * (1.0 + abs(u)):
            return nxt
        u = nxt
    return u


@njit(cache=True, inline="always")
def _along(u, flat, stride, i, n, sign_keep):
    """The two neighbours of ``flat`` along one axis (index ``i`` of ``n``);
    beyond the edge, ``sign_keep * inf``."""
    before = u[flat - stride] if i > 0 else sign_keep * math.inf
    after = u[flat + stride] if i < n - 1 else sign_keep * math.inf
    return before, after


@njit(cache=True, parallel=True)
def sweep(u, target, avoid, kind, speed_a, speed_d, inv_h, mode, order, active, quiet):
    """One Gauss-Seidel sweep of the 4-D array ``u`` in ``order`` (four
    signs); the largest change it made and the nodes it worked.

    ``VALUE``: u <- max(-g, min(l, root, u)), with ``target`` the target's
    function ``l`` and ``avoid`` the avoid set's ``g``. ``TIME``: only nodes
    of ``kind`` ``UPDATE`` change (the rest hold inf outside the winning
    set, ``OUTSIDE``, or 0 on the target, ``FIXED``), and a defender's
    neighbour outside the winning set counts as none: a state the attacker
    wins from has no neighbour it loses from but across the grid's
    resolution. ``active`` marks nodes whose neighbours
    changed by more than ``quiet`` since their last update (uint8, cleared
    as they are worked)."""
    n0, n1, n2, n3 = u.shape
    s0, s1, s2 = n1 * n2 * n3, n2 * n3, n3
    flat = u.reshape(-1)
    low = target.reshape(-1)
    high = avoid.reshape(-1)
    kinds = kind.reshape(-1)
    act = active.reshape(-1)
    ia0, ia1, ib0, ib1 = inv_h[0], inv_h[1], inv_h[2], inv_h[3]
    rhs = 0.0 if mode == VALUE else 1.0
    changes = np.zeros(n0, dtype=np.float64)
    worked = np.zeros(n0, dtype=np.int64)
    for k in range(n0 + n1 - 1):
        first = max(0, k - n1 + 1)
        last = min(k, n0 - 1)
        for j0 in prange(first, last + 1):
            j1 = k - j0
            i0 = j0 if order[0] > 0 else n0 - 1 - j0
            i1 = j1 if order[1] > 0 else n1 - 1 - j1
            va = speed_a[i0, i1]
            worst = changes[j0]
            count = 0
            for j2 in range(n2):
                i2 = j2 if order[2] > 0 else n2 - 1 - j2
                vd_row = speed_d[i2]
                for j3 in range(n3):
                    i3 = j3 if order[3] > 0 else n3 - 1 - j3
                    node = i0 * s0 + i1 * s1 + i2 * s2 + i3
                    if act[node] == 0:
                        continue
                    act[node] = 0
                    if mode == TIME and kinds[node] != UPDATE:
                        continue
                    count += 1
                    p, q = _along(flat, node, s0, i0, n0, 1.0)
                    a0 = min(p, q)
                    p, q = _along(flat, node, s1, i1, n1, 1.0)
                    a1 = min(p, q)
                    p, q = _along(flat, node, s2, i2, n2, -1.0)
                    if mode == TIME:
                        p = p if i2 > 0 and kinds[node - s2] != OUTSIDE else -math.inf
                        q = q if i2 < n2 - 1 and kinds[node + s2] != OUTSIDE else -math.inf
                    b0 = max(p, q)
                    p, q = _along(flat, node, 1, i3, n3, -1.0)
                    if mode == TIME:
                        p = p if i3 > 0 and kinds[node - 1] != OUTSIDE else -math.inf
                        q = q if i3 < n3 - 1 and kinds[node + 1] != OUTSIDE else -math.inf
                    b1 = max(p, q)
                    root = local_root(a0, a1, b0, b1, ia0, ia1, ib0, ib1, va, vd_row[i3], rhs)
                    old = flat[node]
                    new = max(-high[node], min(low[node], root, old)) if mode == VALUE else min(root, old)
                    if new < old:
                        flat[node] = new
                        change = old - new
                        if change > quiet:
                            _wake(act, node, i0, i1, i2, i3, n0, n1, n2, n3, s0, s1, s2)
                        if change > worst:
                            worst = change
            changes[j0] = worst
            worked[j0] += count
    return changes.max(), worked.sum()


@njit(cache=True, inline="always")
def _wake(act, node, i0, i1, i2, i3, n0, n1, n2, n3, s0, s1, s2):
    if i0 > 0:
        act[node - s0] = 1
    if i0 < n0 - 1:
        act[node + s0] = 1
    if i1 > 0:
        act[node - s1] = 1
    if i1 < n1 - 1:
        act[node + s1] = 1
    if i2 > 0:
        act[node - s2] = 1
    if i2 < n2 - 1:
        act[node + s2] = 1
    if i3 > 0:
        act[node - 1] = 1
    if i3 < n3 - 1:
        act[node + 1] = 1


_PAIRED = (0, 15, 1, 14, 2, 13, 4, 11, 8, 7, 3, 12, 5, 10, 6, 9)
ORDERS = np.array([[1 - 2 * ((k >> bit) & 1) for bit in range(4)] for k in _PAIRED], dtype=np.int64)
"""The 16 orderings, each followed by its opposite, so that a front is
carried across the grid both ways before the next pair turns it."""
