"""Maps as GeoJSON files (the schema is in maps/SCHEMA.md).

Files in degrees are plain RFC 7946, so users can draw fields in any GIS
tool; files in metres are easier to write by hand. Every problem found while
reading names the file, the feature and the property at fault.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import Annotated, Any, get_args

import msgspec
import numpy as np
import shapely
from msgspec import Meta
from shapely.geometry import LineString, MultiLineString, MultiPolygon, Point, Polygon, mapping, shape
from shapely.geometry.polygon import orient

from bearcat.maps import geodesy
from bearcat.maps.errors import MapError
from bearcat.maps.model import Map, Region, Role, SpeedFactor, Zone, check_origin, check_polygonal
from bearcat.validation import Invalid, convert, describe

log = logging.getLogger(__name__)

UNITS = ("degrees", "metres")
POLYGONAL = (Polygon, MultiPolygon)
MAX_EXTENT_DEGREES = 0.5
DISK_SEGMENTS = 32
"""Segments per quarter circle of a region drawn as a point and radius (area error below 0.05 %)."""

Label = Annotated[str, Meta(min_length=1)]
Length = Annotated[float, Meta(gt=0.0, le=10000.0, extra={"unit": "m"})]


class _Properties(msgspec.Struct, frozen=True, tag_field="kind"):
    """A feature's ``properties``, by its ``kind``; others (styling from GIS tools) are ignored."""


class AreaProperties(_Properties, tag="area", frozen=True):
    speed: SpeedFactor = 1.0


class ObstacleProperties(_Properties, tag="obstacle", frozen=True):
    name: Label | None = None


class ZoneProperties(_Properties, tag="zone", kw_only=True, frozen=True):
    speed: SpeedFactor
    name: Label | None = None
    width: Length | None = None  # lines only


class RegionProperties(_Properties, tag="region", kw_only=True, frozen=True):
    name: Label
    role: Role
    team: Label | None = None
    radius: Length | None = None  # points only


Properties = AreaProperties | ObstacleProperties | ZoneProperties | RegionProperties
KINDS = tuple(kind.__struct_config__.tag for kind in get_args(Properties))


def read_geojson(path) -> Map:
    """The map in the GeoJSON file at ``path``; its name defaults to the file's stem."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MapError(f"map file {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else "it is not UTF-8 text"
        raise MapError(f"map file {path} cannot be read: {reason}") from None
    return parse_geojson(text, source=f"map file {path}", default_name=path.stem)


def write_geojson(map: Map, path, units: str = "degrees") -> None:
    """Write ``map`` so that ``read_geojson`` gives it back.

    Walkways and disks are written as the polygons they became, and polygons
    follow the RFC 7946 right-hand rule.
    """
    Path(path).write_text(dumps(map, units), encoding="utf-8")


def dumps(map: Map, units: str = "degrees") -> str:
    """The GeoJSON text of ``map``, one feature per line."""
    if units not in UNITS:
        raise ValueError(f"units must be one of {UNITS}, got {units!r}")
    lat, lon = map.origin
    meta = {"name": map.name, "description": map.description, "origin": {"lat": lat, "lon": lon}, "units": units}

    def feature(geometry, **properties) -> str:
        if units == "degrees":
            geometry = shapely.transform(geometry, lambda xy: _to_lonlat(xy, map.origin))
        properties = {k: v for k, v in properties.items() if v is not None}
        return json.dumps({"type": "Feature", "properties": properties, "geometry": mapping(_oriented(geometry))})

    features = [feature(map.area, kind="area", speed=None if map.area_speed == 1 else map.area_speed)]
    assert map.obstacle_names is not None  # a Map fills them in
    features += [feature(o, kind="obstacle", name=n) for o, n in zip(map.obstacles, map.obstacle_names)]
    features += [feature(z.geometry, kind="zone", name=z.name, speed=z.speed) for z in map.zones]
    features += [
        feature(r.geometry, kind="region", name=r.name, role=r.role, team=r.team) for r in map.regions.values()
    ]
    return (
        '{"type": "FeatureCollection",\n"bearcat": '
        + json.dumps(meta)
        + ',\n"features": [\n'
        + ",\n".join(features)
        + "\n]}\n"
    )


def _oriented(geometry):
    if isinstance(geometry, MultiPolygon):
        return MultiPolygon([orient(p) for p in geometry.geoms])
    return orient(geometry)


def _to_lonlat(xy: np.ndarray, origin) -> np.ndarray:
    lat, lon = geodesy.to_geodetic(xy[:, 0], xy[:, 1], origin)
    return np.column_stack([lon, lat])


def _to_metres(lonlat: np.ndarray, origin) -> np.ndarray:
    x, y = geodesy.to_local(lonlat[:, 1], lonlat[:, 0], origin)
    return np.column_stack([x, y])


def parse_geojson(text: str, source: str, default_name: str) -> Map:
    """The map described by GeoJSON ``text``; ``source`` names it in error messages."""
    try:
        document = json.loads(text)
    except json.JSONDecodeError as exc:
        where = f"line {exc.lineno}, column {exc.colno}"
        raise MapError(f"{source} is not valid JSON ({exc.msg} at {where})") from None
    except RecursionError:
        raise MapError(f"{source} nests arrays or objects too deeply to be a map") from None
    if not isinstance(document, dict) or document.get("type") != "FeatureCollection":
        raise MapError(f"{source} is not a GeoJSON FeatureCollection")
    features = document.get("features")
    if not isinstance(features, list):
        raise MapError(f"{source} has no list of features")
    meta = document.get("bearcat", {})
    if not isinstance(meta, dict):
        raise MapError(f"{source}: the 'bearcat' member must be an object")
    units = meta.get("units", "degrees")
    if units not in UNITS:
        raise MapError(f"{source}: bearcat.units must be 'degrees' or 'metres', got {units!r}")
    name = meta.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise MapError(f"{source}: bearcat.name must be a non-empty string, got {name!r}")
    description = meta.get("description", "")
    if not isinstance(description, str):
        raise MapError(f"{source}: bearcat.description must be a string, got {description!r}")

    parsed = [_feature(feature, f"{source}, feature {index}", units) for index, feature in enumerate(features)]
    areas = [index for index, (kind, *_) in enumerate(parsed) if kind == "area"]
    if len(areas) != 1:
        found = "none" if not areas else "features " + ", ".join(str(k) for k in areas)
        raise MapError(f"{source} must have exactly one feature of kind 'area', found {found}")
    _, area_label, area, _ = parsed[areas[0]]
    if units == "degrees":
        _check_extent(area, area_label)
    origin = _origin(meta, source, units, area)
    if units == "degrees":
        parsed = [
            (kind, label, shapely.transform(geometry, lambda c: _to_metres(c, origin)), props)
            for kind, label, geometry, props in parsed
        ]
    try:
        result = Map(name=name, description=description, origin=origin, **_parts(parsed))
    except MapError as exc:
        raise MapError(f"{source}: {exc}") from None
    log.debug("read %s: map %s, %d obstacles, %d zones", source, name, len(result.obstacles), len(result.zones))
    return result


def _parts(parsed) -> dict:
    """Map fields from checked features in metres; strips and disks become polygons here, after any unit change."""
    parts: dict[str, Any] = {"obstacles": [], "obstacle_names": [], "zones": [], "regions": {}}
    for kind, label, geometry, props in parsed:
        try:
            if kind == "area":
                parts["area"], parts["area_speed"] = geometry, props.speed
            elif kind == "obstacle":
                pieces = geometry.geoms if isinstance(geometry, MultiPolygon) else [geometry]
                parts["obstacles"] += pieces
                parts["obstacle_names"] += [props.name] * len(pieces)
            elif kind == "zone":
                if isinstance(geometry, LineString | MultiLineString):
                    geometry = geometry.buffer(props.width / 2, cap_style="flat")
                parts["zones"].append(Zone(props.name, geometry, props.speed))
            else:
                if isinstance(geometry, Point):
                    geometry = geometry.buffer(props.radius, quad_segs=DISK_SEGMENTS)
                if props.name in parts["regions"]:
                    raise MapError(f"property 'name' repeats region name {props.name!r}")
                parts["regions"][props.name] = Region(props.name, props.role, geometry, props.team)
        except MapError as exc:
            raise MapError(f"{label}: {exc}") from None
    return parts


def _check_extent(area, label: str) -> None:
    """Local metres stay accurate over a few kilometres; a wider area is almost always a file in metres."""
    lon_min, lat_min, lon_max, lat_max = area.bounds
    if max(lon_max - lon_min, lat_max - lat_min) > MAX_EXTENT_DEGREES:
        raise MapError(
            f"{label}: the area spans more than {MAX_EXTENT_DEGREES} degrees; "
            'if its coordinates are metres, set "units": "metres" in the bearcat member'
        )


def _origin(meta: dict, source: str, units: str, area) -> tuple[float, float]:
    origin = meta.get("origin")
    if origin is None:
        if units == "metres":
            raise MapError(f"{source}: a map in metres needs bearcat.origin with its lat and lon")
        lon_min, lat_min, _, _ = area.bounds
        return lat_min, lon_min
    if not isinstance(origin, dict) or not all(_is_number(origin.get(k)) for k in ("lat", "lon")):
        raise MapError(f"{source}: bearcat.origin must be an object with numbers 'lat' and 'lon'")
    try:
        return check_origin((origin["lat"], origin["lon"]))
    except MapError as exc:
        raise MapError(f"{source}: {exc}") from None


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _feature(feature, where: str, units: str):
    """``(kind, label, geometry, properties)`` with geometry in the file's units and checked properties."""
    if not isinstance(feature, dict) or feature.get("type") != "Feature":
        raise MapError(f"{where} is not a GeoJSON Feature")
    raw = feature.get("properties")
    if not isinstance(raw, dict):
        raise MapError(f"{where} has no properties object")
    kind = raw.get("kind")
    label = f"{where} ({kind})" if kind in KINDS else where
    try:
        props = convert(raw, Properties)
    except Invalid as exc:
        raise MapError(f"{label}: property {exc.path!r}: {exc.problem}") from None
    geometry = _geometry(feature.get("geometry"), label, units)

    def shapes(*allowed):
        if not isinstance(geometry, allowed):
            names = ", ".join(t.__name__ for t in allowed)
            raise MapError(f"{label}: geometry must be one of {names}; got {geometry.geom_type}")
        if isinstance(geometry, POLYGONAL):
            check_polygonal(geometry, f"{label}: geometry")

    def given(key, shape):
        if getattr(props, key) is None:
            raise MapError(f"{label}: property {key!r}: must be given for a {shape}, as {describe(Length)}")

    if kind == "area":
        shapes(Polygon)
    elif kind == "obstacle":
        shapes(*POLYGONAL)
    elif kind == "zone":
        if isinstance(geometry, LineString | MultiLineString):
            given("width", geometry.geom_type)
        else:
            shapes(*POLYGONAL, LineString, MultiLineString)
    elif isinstance(geometry, Point):
        given("radius", "Point")
    else:
        shapes(*POLYGONAL, Point)
    return kind, label, geometry, props


def _geometry(raw, label: str, units: str):
    if not isinstance(raw, dict):
        raise MapError(f"{label} has no geometry")
    try:
        geometry = shapely.force_2d(shape(raw))
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, shapely.errors.ShapelyError) as exc:
        raise MapError(f"{label}: geometry is not valid GeoJSON ({exc})") from None
    coords = shapely.get_coordinates(geometry)
    if geometry.is_empty or not np.isfinite(coords).all():
        raise MapError(f"{label}: geometry is empty or has coordinates that are not finite numbers")
    if units == "degrees" and ((np.abs(coords[:, 0]) > 180).any() or (np.abs(coords[:, 1]) > 90).any()):
        raise MapError(
            f"{label}: coordinates are not longitude/latitude in degrees; "
            'for a map in metres set "units": "metres" in the bearcat member'
        )
    return geometry
