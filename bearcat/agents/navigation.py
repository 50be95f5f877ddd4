"""Getting somewhere on a map the way a person who knows it would: along the
shortest path around buildings, at the terrain's speeds.

One fast-marching solve per goal gives the travel time to it from every
node; the direction to walk is the first stretch of the steepest-descent
path from where one stands. Solves are cached per goal, so an agent asking
ten times a second pays for one solve, and ``navigator`` keeps one
Navigator per map in a process, so game after game on a map pays for none.
"""

from __future__ import annotations

import math
import weakref

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from bearcat.maps import Map, rasterize
from bearcat.maps.raster import covered
from bearcat.solvers.marching import fmm
from bearcat.solvers.marching.descent import aim_ahead

LOOK_AHEAD = 2.0  # metres along the path the returned direction aims at


class Navigator:
    """Directions toward goals on ``game_map``, on a grid of ``spacing`` metres
    (default: the longer side / 200)."""

    def __init__(self, game_map: Map, spacing: float | None = None) -> None:
        xmin, ymin, xmax, ymax = game_map.bounds
        self.raster = rasterize(game_map, spacing or max(xmax - xmin, ymax - ymin) / 200)
        self.area = game_map.free_space
        self.grid = self.raster.grid
        self._lo, self._hi = np.asarray(self.grid.lo), np.asarray(self.grid.hi)
        # Steps of half a spacing enough to walk LOOK_AHEAD twice over: the
        # path is traced that far, and all the way only where that falls short.
        self._ahead = int(math.ceil(4 * LOOK_AHEAD / min(self.grid.spacing))) + 8
        self._fields: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
        self._goals: dict[tuple[float, ...] | int, tuple[BaseGeometry, tuple[np.ndarray, np.ndarray]]] = {}

    def toward(self, goal, position) -> np.ndarray | None:
        """Unit (east, north) direction from ``position`` along the shortest path
        into ``goal`` (a shapely geometry, or a point); None once inside it or
        if it cannot be reached."""
        goal_geometry, (phi, seeds) = self._goal(goal)
        p = np.asarray(position, float)
        if shapely.intersects_xy(goal_geometry, p[0], p[1]):  # a point intersects what covers it
            return None
        p = np.minimum(np.maximum(p, self._lo), self._hi)  # np.clip's answer, without its checks
        i, j = self.grid.nearest_index(p)
        if not math.isfinite(phi[i, j]):
            return None
        found = aim_ahead(self.grid, phi, seeds, p, self._ahead, LOOK_AHEAD)
        if found is None:
            return None
        aim, points = found
        if points == 1:
            aim = np.asarray(goal_geometry.centroid.coords[0])
        d = aim - p
        n = math.hypot(d[0], d[1])
        return d / n if n > 1e-9 else None

    def _goal(self, goal) -> tuple[BaseGeometry, tuple[np.ndarray, np.ndarray]]:
        """``goal`` as a prepared geometry, with its field. A walker asks ten
        times a second for the same goal: a point by its coordinates, a
        geometry by identity (it is held here, so its id stays its own)."""
        point = tuple(float(v) for v in goal) if isinstance(goal, tuple | list | np.ndarray) else None
        handle = id(goal) if point is None else point
        found = self._goals.get(handle)
        if found is None:
            geometry = goal if point is None else shapely.Point(point)
            shapely.prepare(geometry)
            found = self._goals[handle] = (geometry, self._field(geometry))
        return found

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
            found = (np.ascontiguousarray(phi, np.float64), np.ascontiguousarray(seeds, np.bool_))
            self._fields[key] = found
        return found


_navigators: weakref.WeakKeyDictionary[Map, Navigator] = weakref.WeakKeyDictionary()


def navigator(game_map: Map) -> Navigator:
    """The Navigator of ``game_map`` at the default spacing, the same one for
    every game on that map while the map lives."""
    found = _navigators.get(game_map)
    if found is None:
        found = _navigators[game_map] = Navigator(game_map)
    return found
