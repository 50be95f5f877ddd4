"""Regions and lines as guidance carries them: rings and lines of WGS84
``[lon, lat]`` points (GeoJSON's order, as the maps use), at most
``MAX_LINES`` of up to ``MAX_LINE_POINTS`` points each, the limits the
message schema enforces."""

from __future__ import annotations

import contourpy
import numpy as np
import shapely

from bearcat.maps import Map

MAX_LINES = 64
MAX_LINE_POINTS = 4096


def on_the_wire(game_map: Map, lines) -> list[list[tuple[float, float]]]:
    """``lines`` (arrays of map-metre points) as ``[lon, lat]`` lists, cut to the schema's limits."""
    out = []
    for line in lines[:MAX_LINES]:
        line = np.asarray(line)[:MAX_LINE_POINTS]
        lat, lon = game_map.to_geodetic(line[:, 0], line[:, 1])
        out.append(list(zip(np.atleast_1d(lon).tolist(), np.atleast_1d(lat).tolist())))
    return out


def polygon_rings(region, tolerance: float) -> list[np.ndarray]:
    """The exterior rings of a shapely (Multi)Polygon, a ring of more points
    than the wire carries simplified by ``tolerance`` metres first."""
    rings = []
    for polygon in shapely.get_parts(region):
        ring = polygon.exterior
        if len(ring.coords) > MAX_LINE_POINTS:
            ring = ring.simplify(tolerance)
        rings.append(np.asarray(ring.coords))
    return rings


def mask_rings(grid, mask: np.ndarray) -> list[np.ndarray]:
    """The outlines of a set of grid nodes, traced halfway to the nodes outside, longest first."""
    if not mask.any():
        return []
    x, y = grid.axes()
    lines = contourpy.contour_generator(x, y, mask.T.astype(float), line_type="Separate").lines(0.5)
    return sorted((line for line in lines if len(line) >= 4), key=len, reverse=True)
