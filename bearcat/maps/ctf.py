"""A map as the capture-the-flag solver sees it: signed distances and terrain
on the grid of one player's position."""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import box

from bearcat.maps.distance import signed_distance
from bearcat.maps.errors import MapError
from bearcat.maps.model import Map
from bearcat.maps.raster import rasterize
from bearcat.solvers.ctf.sets import CtfGeometry
from bearcat.solvers.grid import Grid

MIN_GRID_POINTS = 9


def ctf_geometry(game_map: Map, grid_points: int) -> CtfGeometry:
    """The capture-the-flag geometry of ``game_map`` on ``grid_points`` nodes
    per axis spanning its bounds, so the grid's edges are the area's edges.
    Flag and return regions are the unions of the map's regions with those
    roles."""
    if not isinstance(grid_points, int) or grid_points < MIN_GRID_POINTS:
        raise MapError(f"a capture-the-flag grid needs at least {MIN_GRID_POINTS} points per axis, got {grid_points!r}")
    xmin, ymin, xmax, ymax = game_map.bounds
    grid = Grid.spanning((xmin, ymin), (xmax, ymax), (grid_points, grid_points))
    flag = _role_union(game_map, "flag")
    home = _role_union(game_map, "return")
    blocked = box(xmin, ymin, xmax, ymax).difference(game_map.free_space)
    if blocked.is_empty:
        # Nothing is blocked: any distance beyond the box's diagonal will do.
        blocked_distance = np.full(grid.shape, 2.0 * float(np.hypot(xmax - xmin, ymax - ymin)))
    else:
        blocked_distance = signed_distance(blocked, grid)
    flag_distance, home_distance = signed_distance(flag, grid), signed_distance(home, grid)
    terrain = rasterize(game_map, grid=grid).speed
    for distance, label in ((flag_distance, "flag"), (home_distance, "return")):
        if not (distance <= 0).any():
            raise MapError(
                f"the {label} region of map {game_map.name} covers no node of a {grid_points} x {grid_points} "
                "grid; use more grid points"
            )
    return CtfGeometry(grid=grid, blocked=blocked_distance, flag=flag_distance, home=home_distance, terrain=terrain)


def _role_union(game_map: Map, role: str):
    regions = game_map.regions_with_role(role)
    if not regions:
        raise MapError(
            f"map {game_map.name} has no {role} region; capture-the-flag needs a flag region and a return region"
        )
    return shapely.union_all([r.geometry for r in regions])
