"""WGS84 latitude/longitude to and from a map's local east/north metres.

This is the only place where the conversion happens. Local coordinates are
the azimuthal equidistant projection centred on the map's origin (PROJ's
``aeqd`` on the WGS84 ellipsoid): distances and bearings from the origin are
exact, and over the few kilometres of a playing field it agrees with the
east/north tangent plane to well under a millimetre. PROJ does it in C, a
microsecond or two a point, which matters when every fix, truth report and
guidance polygon crosses it. A single point goes to PROJ as plain floats,
through pyproj's path for one point: the same numbers as through arrays, at a
fifth of the cost (building arrays for one point was most of it).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from pyproj import CRS, Transformer


@lru_cache(maxsize=32)
def _transformers(origin: tuple[float, float]) -> tuple[Transformer, Transformer]:
    lat0, lon0 = origin
    local = CRS.from_proj4(f"+proj=aeqd +lat_0={lat0!r} +lon_0={lon0!r} +datum=WGS84 +units=m +no_defs")
    forward = Transformer.from_crs("EPSG:4326", local, always_xy=True)
    inverse = Transformer.from_crs(local, "EPSG:4326", always_xy=True)
    return forward, inverse


def _output(value):
    array = np.asarray(value, dtype=float)
    return float(array) if array.ndim == 0 else array


def _point(a, b) -> bool:
    """Whether ``a`` and ``b`` are one coordinate each rather than arrays
    (floats, numpy's included, are asked first: they are most of the calls)."""
    return (isinstance(a, float) or np.ndim(a) == 0) and (isinstance(b, float) or np.ndim(b) == 0)


def to_local(lat, lon, origin: tuple[float, float]):
    """East/north metres of ``(lat, lon)`` in degrees; arrays broadcast, scalars give floats."""
    forward, _ = _transformers((float(origin[0]), float(origin[1])))
    if _point(lat, lon):
        return forward.transform(float(lon), float(lat))
    lat, lon = np.broadcast_arrays(np.asarray(lat, dtype=float), np.asarray(lon, dtype=float))
    east, north = forward.transform(lon, lat)
    return _output(east), _output(north)


def to_geodetic(x, y, origin: tuple[float, float]):
    """``(lat, lon)`` in degrees of the point at east/north metres ``(x, y)``."""
    _, inverse = _transformers((float(origin[0]), float(origin[1])))
    if _point(x, y):
        lon, lat = inverse.transform(float(x), float(y))
        return lat, lon
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    lon, lat = inverse.transform(x, y)
    return _output(lat), _output(lon)


def bearing(east: float, north: float) -> float:
    """Degrees clockwise from north of an (east, north) direction, in [0, 360).

    Headings cross the wire in this form. A float remainder such as
    ``-1e-17 % 360.0`` rounds up to 360.0, which the wire's range refuses,
    so that case folds to 0 here, once for every caller.
    """
    return compass_degrees(math.atan2(east, north))


def compass_degrees(radians: float) -> float:
    """A heading in radians clockwise from north as degrees in [0, 360)."""
    degrees = math.degrees(radians) % 360.0
    return 0.0 if degrees >= 360.0 else degrees
