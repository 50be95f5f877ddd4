"""The evader's safe-reachable set ``S_e`` from cached travel times (thesis
4.1.3, 4.1.5, 5.2.2): one plain front per pursuer, its capture min-filter,
and one front from the evader capped by the least of them."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from bearcat.solvers.errors import InputError, non_negative, positive
from bearcat.solvers.marching import fmm
from bearcat.solvers.pursuit.fmm.travel_times import TravelTimes

__all__ = ["SafeSet", "check_pursuer_speeds", "march_safe_set", "safe_set"]


@dataclass(frozen=True, eq=False)
class SafeSet:
    """The evader's safe-reachable set ``S_e`` on the travel times' grid.

    ``mask`` marks the nodes of ``S_e``; ``area`` is ``N_s h^2``.
    ``evader_time`` is the evader's arrival time ``phi`` along safe paths
    (infinite outside ``S_e``); ``pursuer_times[i]`` is pursuer ``i``'s time
    to capture ``psi_i^c`` (N, nx, ny); ``owner`` is the pursuer with the
    least ``psi^c`` at each node, the one that bounds ``S_e`` there (-1 where
    no pursuer can come). Arrays are read-only: caches share them.
    """

    mask: np.ndarray
    area: float
    evader_time: np.ndarray
    pursuer_times: np.ndarray
    owner: np.ndarray

    @property
    def capture_time(self) -> np.ndarray:
        """``psi^c = min_i psi_i^c``, the ceiling the evader's front ran under."""
        if len(self.pursuer_times) == 0:
            return np.full(self.mask.shape, np.inf)
        return self.pursuer_times.min(axis=0)


def safe_set(
    travel_times: TravelTimes,
    evader,
    pursuers,
    *,
    evader_speed: float = 1.0,
    pursuer_speeds=1.0,
    capture_radius: float = 0.5,
) -> SafeSet:
    """``S_e``: the nodes the evader reaches strictly before every pursuer's
    time to capture, along paths of such nodes (thesis 4.1.3, 4.1.5, 5.2.2).

    Speeds scale the speed factor of ``travel_times``; ``pursuer_speeds`` is
    one number or one per pursuer. An evader already within the capture
    radius of a pursuer has an empty set.
    """
    e = travel_times.check_point(evader, "evader")
    ps = travel_times.check_points(pursuers, "pursuers")
    speeds = check_pursuer_speeds(pursuer_speeds, len(ps))
    ve = positive(evader_speed, "evader speed")
    return march_safe_set(travel_times, e, ps, ve, speeds, non_negative(capture_radius, "capture radius"))


def march_safe_set(
    travel_times: TravelTimes, e: np.ndarray, ps: np.ndarray, ve: float, speeds, radius: float, *, keep: bool = True
) -> SafeSet:
    """``safe_set`` for callers that have checked their inputs. The last set
    built with ``keep`` is kept with the travel times, for the next caller
    asking about the same state."""
    key = ("safe set", tuple(e), tuple(map(tuple, ps)), ve, tuple(speeds), radius)
    return travel_times.derived(key, lambda: _march(travel_times, e, ps, ve, speeds, radius), keep=keep)


def check_pursuer_speeds(value, n: int | None) -> np.ndarray:
    """``value``, one speed or one per pursuer, as an array of ``n`` speeds
    (as given without ``n``); an InputError unless all are positive and finite."""
    s = np.asarray(value, dtype=np.float64)
    if s.ndim > 1 or not (np.isfinite(s) & (s > 0)).all():
        raise InputError(f"pursuer speeds must be positive finite numbers, got {value!r}")
    if n is None:
        return s
    if s.ndim == 1 and s.size != n:
        raise InputError(f"got {s.size} pursuer speeds for {n} pursuers")
    return np.broadcast_to(s, (n,)).astype(np.float64)


def _march(travel_times: TravelTimes, e, ps, ve: float, speeds, radius: float) -> SafeSet:
    g = travel_times.grid
    hx, hy = travel_times.spacing
    n = len(ps)
    psic = np.empty((n,) + g.shape)
    for k, (p, s) in enumerate(zip(ps, speeds)):
        np.divide(travel_times.front(p).capture_time(radius), s, out=psic[k])
    owner, ceiling = _owner(psic)
    if n and np.hypot(*(ps - e).T).min() <= radius:
        phi = np.full(g.shape, np.inf)  # captured already
    else:
        # The evader's front at speed factor 1 under the ceiling in the same units.
        initial = fmm.point_source(g, e, travel_times.speed)
        phi = fmm.march(travel_times.speed, hx, hy, initial, ceiling * ve, travel_times.order)
        phi /= ve
    mask = np.isfinite(phi)
    for a in (mask, phi, psic, owner):
        a.flags.writeable = False
    area = float(mask.sum()) * g.cell_area
    return SafeSet(mask=mask, area=area, evader_time=phi, pursuer_times=psic, owner=owner)


@numba.njit(cache=True)
def _owner(psic):
    """The pursuer with the least time to capture at each node (-1 where none
    comes), and that time: ``psi^c = min_i psi_i^c``, the evader's ceiling."""
    n, nx, ny = psic.shape
    owner = np.full((nx, ny), -1, dtype=np.int64)
    ceiling = np.full((nx, ny), np.inf)
    for k in range(n):
        for i in range(nx):
            for j in range(ny):
                if psic[k, i, j] < ceiling[i, j]:
                    ceiling[i, j] = psic[k, i, j]
                    owner[i, j] = k
    return owner, ceiling
