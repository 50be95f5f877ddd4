"""Who may know whose position: the sensing the ground station simulates.

In the limited-visibility game of thesis 6.2 nobody is told where an
opponent is unless someone on their side can see it: "whenever the
defender entered V_A both the defender and attacker received information
about each other's locations, and when the defender entered V_Q the
attacker was alerted to the defender position" (6.2.4). Teammates and
their own UAVs always know each other. Line of sight runs between the
reported positions (what the ground station has), blocked by the map's
buildings. With full visibility everybody knows everything, as in the
games of chapter 3.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import shapely

from bearcat.maps import Map


class Sight:
    """Visibility between the agents of ``teams`` (agent -> team, UAVs
    included); ``uavs`` fly above the buildings and are known to their own
    side only."""

    def __init__(self, game_map: Map, teams: Mapping[str, str], *, line_of_sight: bool, uavs=()) -> None:
        self.teams = dict(teams)
        self.uavs = frozenset(uavs)
        self.line_of_sight = line_of_sight
        self._walls = shapely.union_all(game_map.obstacles) if game_map.obstacles else None
        if self._walls is not None:
            shapely.prepare(self._walls)

    def allies(self, a: str, b: str) -> bool:
        return a == b or (a in self.teams and self.teams.get(a) == self.teams.get(b))

    def sees(self, a, b) -> bool:
        """Whether map points ``a`` and ``b`` are in each other's line of sight."""
        if not self.line_of_sight or self._walls is None:
            return True
        a, b = np.asarray(a, float), np.asarray(b, float)
        if np.allclose(a, b):
            return True
        return not self._walls.intersects(shapely.LineString([a, b]))

    def side(self, team: str) -> list[str]:
        return [agent for agent, t in self.teams.items() if t == team]
