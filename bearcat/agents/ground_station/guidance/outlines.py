"""Regions and lines as guidance carries them: rings and lines of WGS84
``[lon, lat]`` points (GeoJSON's order, as the maps use), within the
message's limits on lines and points per outline."""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import contourpy
import numpy as np
import shapely

from bearcat.bus.messages import OUTLINE_LINES, OUTLINE_POINTS
from bearcat.maps import Map

if TYPE_CHECKING:
    from contourpy._contourpy import LineReturn_Separate


def on_the_wire(game_map: Map, lines, tolerance: float = 0.25) -> list[list[tuple[float, float]]]:
    """``lines`` (arrays of map-metre points) as ``[lon, lat]`` lists.

    The longest ``OUTLINE_LINES`` lines are kept. While they hold more than
    ``OUTLINE_POINTS`` points in all, each is simplified (Douglas-Peucker,
    which keeps a ring closed) with a tolerance that doubles from
    ``tolerance`` metres, so an outline loses detail rather than parts.
    """
    kept = sorted((np.asarray(line, dtype=float) for line in lines), key=len, reverse=True)[:OUTLINE_LINES]
    while sum(len(line) for line in kept) > OUTLINE_POINTS:
        kept = [np.asarray(shapely.LineString(line).simplify(tolerance).coords) for line in kept]
        tolerance *= 2.0
    out = []
    for line in kept:
        lat, lon = game_map.to_geodetic(line[:, 0], line[:, 1])
        out.append(list(zip(np.atleast_1d(lon).tolist(), np.atleast_1d(lat).tolist())))
    return out


def polygon_rings(region) -> list[np.ndarray]:
    """The exterior rings of a shapely (Multi)Polygon."""
    return [np.asarray(polygon.exterior.coords) for polygon in shapely.get_parts(region)]


def mask_rings(grid, mask: np.ndarray) -> list[np.ndarray]:
    """The outlines of a set of grid nodes, traced halfway to the nodes outside, longest first."""
    if not mask.any():
        return []
    x, y = grid.axes()
    generator = contourpy.contour_generator(x, y, mask.T.astype(float), line_type="Separate")
    lines = cast("LineReturn_Separate", generator.lines(0.5))  # as line_type says
    return sorted((line for line in lines if len(line) >= 4), key=len, reverse=True)
