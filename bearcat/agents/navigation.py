"""Getting somewhere on a map the way a person who knows it would: along the
shortest path around buildings, at the terrain's speeds.

One fast-marching solve per goal gives the travel time to it from every
node; the direction to walk is the first stretch of the steepest-descent
path from where one stands. Solves are cached per goal, so an agent asking
ten times a second pays for one solve.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from bearcat.maps import Map, rasterize
from bearcat.maps.raster import covered
from bearcat.solvers import fmm
from bearcat.solvers.descent import descend

LOOK_AHEAD = 2.0  # metres along the path the returned direction aims at


class Navigator:
    """Directions toward goals on ``game_map``, on a grid of ``spacing`` metres
    (default: the longer side / 200)."""

    def __init__(self, game_map: Map, spacing: float | None = None) -> None:
        xmin, ymin, xmax, ymax = game_map.bounds
        self.raster = rasterize(game_map, spacing or max(xmax - xmin, ymax - ymin) / 200)
        self.area = game_map.free_space
        self.grid = self.raster.grid
        self._fields: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def toward(self, goal, position) -> np.ndarray | None:
        """Unit (east, north) direction from ``position`` along the shortest path
        into ``goal`` (a shapely geometry); None once inside it or if it cannot
        be reached."""
        goal_geometry = goal if not isinstance(goal, tuple | list | np.ndarray) else shapely.Point(goal)
        p = np.asarray(position, float)
        if goal_geometry.covers(shapely.Point(p)):
            return None
        phi, seeds = self._field(goal_geometry)
        p = np.clip(p, self.grid.lo, self.grid.hi)
        i, j = self.grid.nearest_index(p)
        if not math.isfinite(phi[i, j]):
            return None
        try:
            path = descend(self.grid, phi, p, seeds=seeds).points
        except ValueError:
            return None
        along = np.cumsum(np.r_[0.0, np.hypot(*np.diff(path, axis=0).T)])
        k = int(np.searchsorted(along, LOOK_AHEAD))
        aim = path[min(k, len(path) - 1)] if len(path) > 1 else np.asarray(goal_geometry.centroid.coords[0])
        d = aim - p
        n = math.hypot(d[0], d[1])
        return d / n if n > 1e-9 else None

    def _field(self, goal) -> tuple[np.ndarray, np.ndarray]:
        key = shapely.to_wkb(goal)
        found = self._fields.get(key)
        if found is None:
            seeds = covered(goal, self.grid) & self.raster.free
            if not seeds.any():  # a goal smaller than a cell: its nearest free node
                seeds = np.zeros(self.grid.shape, bool)
                seeds[self.grid.nearest_index(np.asarray(goal.centroid.coords[0]))] = True
                seeds &= self.raster.free
            initial = np.where(seeds, 0.0, np.inf)
            phi = fmm.travel_time(self.raster.speed, self.grid.spacing, initial)
            found = (phi, seeds)
            self._fields[key] = found
        return found
