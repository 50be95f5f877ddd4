"""Signed distances from grid nodes to map geometry, the level-set form of a region.

Level-set solvers represent a set as the sub-zero set of a function; the
exact Euclidean distance to the geometry's boundary (negative inside) keeps
the set boundary at sub-cell accuracy on the coarse grids HJI solvers use,
where a rasterised mask would move it by up to a cell.
"""

from __future__ import annotations

import numpy as np
import shapely

from bearcat.solvers.grid import Grid


def signed_distance(geometry, grid: Grid) -> np.ndarray:
    """Metres from each node of the 2-D ``grid`` to the boundary of ``geometry``:
    negative inside, zero on the boundary, positive outside."""
    if grid.ndim != 2:
        raise ValueError(f"signed distances need a 2-D grid, got {grid.ndim}-D")
    x, y = grid.mesh()
    points = shapely.points(x.ravel(), y.ravel())
    distance = shapely.distance(geometry.boundary, points)
    inside = shapely.intersects_xy(geometry, x.ravel(), y.ravel())
    return np.where(inside, -distance, distance).reshape(grid.shape)
