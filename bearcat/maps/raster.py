"""A map laid on a grid: the speed factor at every node and one mask per region.

Nodes are classified with the closed free space (area boundary and obstacle
edges included, obstacle interiors excluded) and closed zones and regions;
see ``maps.scanline`` for how nodes on an edge are recognised.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from bearcat.maps.errors import MapError
from bearcat.maps.model import Map
from bearcat.maps.scanline import coverage
from bearcat.solvers.grid import Grid

log = logging.getLogger(__name__)

MAX_NODES = 100_000_000
"""A larger raster would not fit in memory; a spacing that asks for one is a mistake."""


@dataclass(frozen=True, eq=False)
class Raster:
    """``speed[ix, iy]`` is the speed factor (0 in obstacles and outside the area).

    ``masks[name][ix, iy]`` marks the free nodes of region ``name``: a region
    drawn over a building does not put target nodes inside it.
    """

    grid: Grid
    speed: np.ndarray
    masks: dict[str, np.ndarray]

    @property
    def free(self) -> np.ndarray:
        return self.speed > 0


def covered(geometry, grid: Grid) -> np.ndarray:
    """Boolean array over ``grid``: the nodes ``geometry`` covers (boundary included)."""
    mask = np.zeros(grid.shape, dtype=bool)
    found = coverage(geometry, *grid.axes())
    if found is not None:
        mask[found.window] = found.covers
    return mask


def rasterize(map: Map, spacing: float | None = None, *, grid: Grid | None = None) -> Raster:
    """Lay ``map`` on ``grid``, or on a grid of ``spacing`` metres from the area's south-west corner."""
    if (spacing is None) == (grid is None):
        raise TypeError("rasterize needs exactly one of spacing and grid")
    if grid is None:
        assert spacing is not None  # exactly one of them was given
        xmin, ymin, xmax, ymax = map.bounds
        grid = Grid.covering((xmin, ymin), (xmax, ymax), spacing)
    if grid.ndim != 2:
        raise ValueError(f"a map raster needs a 2-D grid, got {grid.ndim}-D")
    if grid.size > MAX_NODES:
        raise MapError(
            f"a grid of {grid.shape[0]} x {grid.shape[1]} nodes for map {map.name} is too large "
            f"(limit {MAX_NODES:,}); use a coarser spacing"
        )
    xs, ys = grid.axes()
    speed = np.full(grid.shape, map.area_speed)
    for zone in map.zones:
        found = coverage(zone.geometry, xs, ys)
        if found is not None:
            speed[found.window][found.covers] = zone.speed
    free = covered(map.free_space, grid)
    speed[~free] = 0.0
    masks = {name: covered(region.geometry, grid) & free for name, region in map.regions.items()}
    log.debug("rasterised map %s on %d x %d nodes", map.name, *grid.shape)
    return Raster(grid, speed, masks)
