"""What an advisor answers from: the latest fix of each agent, in map metres.

Fixes are what the network delivered, GPS error included, so one may put an
agent inside a building or off the map; ``nearest_inside`` moves it to the
nearest free point before a solver is asked, as a person's phone would still
show them somewhere.
"""

from __future__ import annotations

import numpy as np
import shapely
import shapely.ops

from bearcat.bus.messages import Fix, Report
from bearcat.maps import Map


class LatestFixes:
    """The latest fix per agent, in map metres, ignoring fixes older than the one held."""

    def __init__(self, game_map: Map) -> None:
        self.map = game_map
        self.latest: dict[str, tuple[np.ndarray, float, Fix]] = {}

    def take(self, fix: Fix) -> bool:
        """Keep ``fix`` if it is newer than the one held; whether it was."""
        held = self.latest.get(fix.agent)
        if held is None or fix.t > held[1]:
            self.latest[fix.agent] = (np.array(self.map.to_local(fix.lat, fix.lon)), fix.t, fix)
            return True
        return False

    def reports(self) -> list[Report]:
        return [Report(agent, f.t, f.lat, f.lon) for agent, (_, _, f) in self.latest.items()]


def nearest_inside(inside, point) -> np.ndarray:
    """The point of the shapely geometry ``inside`` nearest ``point`` (map metres)."""
    return np.asarray(shapely.ops.nearest_points(inside, shapely.Point(point))[0].coords[0])
