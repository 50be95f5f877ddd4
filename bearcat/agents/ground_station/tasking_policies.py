"""The built-in UAV tasking policies of thesis 6.2, entries of ``tasking.TASKING``
exactly as a user's own are:

- ``reachability``: the hierarchy of eqs. 6.7-6.9 (``solvers.search.search_target``);
- ``lawnmower``: a sweep of the map in strips one camera footprint apart,
  UAV k of n starting k/n of the way along it;
- ``nearest``: the nearest place the defender may be and nobody looks at.
"""

from __future__ import annotations

import numpy as np

from bearcat.agents.ground_station.tasking import NEEDS_SETS, SearchView, TaskingPolicy, Uav
from bearcat.solvers import search


class Reachability(TaskingPolicy):
    """The thesis's hierarchy: search where the defender may reach the attacker unseen first (6.2)."""

    traits = frozenset({NEEDS_SETS})

    def next_point(self, uav: Uav, view: SearchView):
        found = search.search_target(
            view.terrain,
            view.grid,
            view.possible,
            view.seen_by_attacker,
            view.seen_by_uavs,
            view.defender_wins(),
            attacker=view.attacker,
            uav=view.at,
            defender_speed=view.defender_speed,
            uav_speed=uav.speed,
            uav_radius=uav.camera_radius,
        )
        return found.target, found.tier


class Lawnmower(TaskingPolicy):
    """Sweep the map in strips a camera footprint apart, each UAV from its own share of the way."""

    def __init__(self, options, rng: np.random.Generator) -> None:
        self.sweeps: dict[str, list] = {}  # UAV -> [waypoints, index]

    def next_point(self, uav: Uav, view: SearchView):
        if uav.name not in self.sweeps:
            path = search.lawnmower(view.map.bounds, uav.camera_radius, start=view.at)
            k = [v.name for v in view.uavs].index(uav.name)
            self.sweeps[uav.name] = [path, k * len(path) // len(view.uavs)]
        path, index = self.sweeps[uav.name]
        if np.hypot(*(path[index] - view.at)) <= max(2.0, 0.2 * uav.camera_radius):
            self.sweeps[uav.name][1] = index = (index + 1) % len(path)
        x, y = path[index]
        return (float(x), float(y)), None


class Nearest(TaskingPolicy):
    """Fly to the nearest place the defender may be that nobody looks at."""

    def next_point(self, uav: Uav, view: SearchView):
        return search.nearest_unobserved(view.grid, view.possible, view.at), None


BUILTINS: dict[str, type] = {"reachability": Reachability, "lawnmower": Lawnmower, "nearest": Nearest}
"""The built-in entries of ``tasking.TASKING``, by the names scenarios give them."""
