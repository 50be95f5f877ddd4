"""A UAV that escorts the attacker: it looks where the unseen defender may
be nearest the attacker, since that is where a threat comes from first.
UAV k of n takes the k-th nearest such place at least ``apart`` metres
from the ones before it, so two UAVs do not watch the same ground."""

from __future__ import annotations

import numpy as np

from bearcat.plugins import Distance, Options, TaskingPolicy


class Escort(TaskingPolicy):
    """Look where the defender may be nearest the attacker."""

    class Options(Options, frozen=True):
        apart: Distance = 20.0

    def __init__(self, options: Escort.Options, rng: np.random.Generator) -> None:
        self.apart = options.apart

    def next_point(self, uav, view):
        ix, iy = np.nonzero(view.possible)
        if len(ix) == 0:
            return None
        points = np.stack([view.grid.axes()[0][ix], view.grid.axes()[1][iy]], axis=1)
        order = np.argsort(np.hypot(*(points - view.attacker).T))
        k = [u.name for u in view.uavs].index(uav.name)
        chosen: list[np.ndarray] = []
        for i in order:
            if all(np.hypot(*(points[i] - c)) >= self.apart for c in chosen):
                chosen.append(points[i])
                if len(chosen) > k:
                    break
        x, y = chosen[min(k, len(chosen) - 1)]
        return (float(x), float(y)), None
