"""WGS84 latitude/longitude to and from a map's local east/north metres.

This is the only place where the conversion happens. Local coordinates are
the east/north components of the tangent plane at the map origin (pymap3d's
ENU frame), for points on the ellipsoid surface (altitude 0).
"""

from __future__ import annotations

import numpy as np
import pymap3d

# The ellipsoid point whose tangent-plane projection is (x, y) lies slightly
# below the plane; two corrections of the height bring it to the surface to
# well below a nanometre over kilometres, which makes the two conversions
# exact inverses.
_SURFACE_ITERATIONS = 3


def _output(value):
    array = np.asarray(value, dtype=float)
    return float(array) if array.ndim == 0 else array


def to_local(lat, lon, origin: tuple[float, float]):
    """East/north metres of ``(lat, lon)`` in degrees; arrays broadcast, scalars give floats."""
    lat0, lon0 = origin
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    east, north, _ = pymap3d.geodetic2enu(lat, lon, np.zeros_like(lat), lat0, lon0, 0.0)
    return _output(east), _output(north)


def to_geodetic(x, y, origin: tuple[float, float]):
    """``(lat, lon)`` in degrees of the surface point at east/north metres ``(x, y)``."""
    lat0, lon0 = origin
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    up = np.zeros(np.broadcast(x, y).shape)
    for _ in range(_SURFACE_ITERATIONS):
        lat, lon, height = pymap3d.enu2geodetic(x, y, up, lat0, lon0, 0.0)
        up = up - height
    return _output(lat), _output(lon)
