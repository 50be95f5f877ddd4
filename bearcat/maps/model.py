"""The map model: a playing area with obstacles, terrain zones and named regions.

Geometry is shapely, in local metres (x east, y north) around a geodetic
origin. The model is immutable once built, so a map can be shared by every
agent and solver of a game without copies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Annotated, Literal, get_args

import shapely
from msgspec import Meta
from shapely.geometry import MultiPolygon, Point, Polygon

from bearcat.maps import geodesy
from bearcat.maps.errors import MapError
from bearcat.validation import Invalid, convert

Role = Literal["flag", "return", "target", "side"]
ROLES: tuple[Role, ...] = get_args(Role)

SpeedFactor = Annotated[float, Meta(gt=0.0, le=1.0)]
"""Zero would be an obstacle, and nothing is faster than full speed."""


def check_speed(value, what: str) -> float:
    """``value`` as a speed factor, else a MapError naming ``what``."""
    try:
        return convert(value, SpeedFactor)
    except Invalid as exc:
        raise MapError(f"{what} {exc.problem}") from None


def check_origin(origin) -> tuple[float, float]:
    try:
        lat, lon = (float(v) for v in origin)
    except (TypeError, ValueError):
        raise MapError(f"map origin must be a (lat, lon) pair, got {origin!r}") from None
    if not (math.isfinite(lat) and math.isfinite(lon) and -90 <= lat <= 90 and -180 <= lon <= 180):
        raise MapError(f"map origin ({lat}, {lon}) is not a latitude in [-90, 90] and a longitude in [-180, 180]")
    return lat, lon


def check_polygonal(geometry, what: str, kinds=(Polygon, MultiPolygon)) -> None:
    if not isinstance(geometry, kinds):
        names = " or ".join(k.__name__ for k in kinds)
        raise MapError(f"{what} must be a {names}, got {type(geometry).__name__}")
    if not geometry.is_valid:
        raise MapError(f"{what} is not a valid polygon ({shapely.is_valid_reason(geometry)})")
    if geometry.area <= 0:
        raise MapError(f"{what} has no area")


@dataclass(frozen=True)
class Zone:
    """Terrain where agents move at ``speed`` times their top speed (walkways 1, vegetation less)."""

    name: str | None
    geometry: Polygon | MultiPolygon
    speed: float

    def __post_init__(self) -> None:
        what = f"zone {self.name!r}" if self.name else "zone"
        check_polygonal(self.geometry, f"geometry of {what}")
        object.__setattr__(self, "speed", check_speed(self.speed, f"speed of {what}"))


@dataclass(frozen=True)
class Region:
    """A named part of the map with a role in a game: a flag, a return (safe) region, a target, a team's side."""

    name: str
    role: str
    geometry: Polygon | MultiPolygon
    team: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise MapError(f"a region name must be a non-empty string, got {self.name!r}")
        if self.role not in ROLES:
            raise MapError(f"region {self.name!r} has role {self.role!r}; roles are {', '.join(ROLES)}")
        check_polygonal(self.geometry, f"geometry of region {self.name!r}")


@dataclass(frozen=True, eq=False)
class Map:
    """A playing field.

    ``obstacles`` are impassable polygons; ``obstacle_names`` runs alongside
    them (``None`` where unnamed). ``zones`` are painted in order over
    ``area_speed``, later ones overriding earlier ones. The free space is the
    closed set ``area - obstacles``: area boundaries and obstacle edges are
    walkable.
    """

    name: str
    area: Polygon
    origin: tuple[float, float]
    obstacles: tuple[Polygon, ...] = ()
    obstacle_names: tuple[str | None, ...] | None = None
    zones: tuple[Zone, ...] = ()
    regions: dict[str, Region] = field(default_factory=dict)
    area_speed: float = 1.0
    description: str = ""

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        check_polygonal(self.area, f"area of map {self.name}", kinds=(Polygon,))
        set_(self, "origin", check_origin(self.origin))
        set_(self, "area_speed", check_speed(self.area_speed, f"area speed of map {self.name}"))
        set_(self, "obstacles", tuple(self.obstacles))
        for index, obstacle in enumerate(self.obstacles):
            check_polygonal(obstacle, f"obstacle #{index} of map {self.name}", kinds=(Polygon,))
        names = (None,) * len(self.obstacles) if self.obstacle_names is None else tuple(self.obstacle_names)
        if len(names) != len(self.obstacles):
            raise MapError(f"map {self.name} has {len(self.obstacles)} obstacles but {len(names)} obstacle names")
        set_(self, "obstacle_names", names)
        set_(self, "zones", tuple(self.zones))
        set_(self, "regions", dict(self.regions))
        for key, region in self.regions.items():
            if key != region.name:
                raise MapError(f"map {self.name} files region {region.name!r} under the key {key!r}")
            if not region.geometry.intersects(self.free_space):
                raise MapError(f"region {region.name!r} of map {self.name} lies entirely outside its free space")

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the area in metres."""
        xmin, ymin, xmax, ymax = self.area.bounds
        return float(xmin), float(ymin), float(xmax), float(ymax)

    @cached_property
    def free_space(self):
        """Where agents can be. Obstacles are merged first, so abutting obstacles leave no seam to walk through."""
        return self.area.difference(shapely.union_all(self.obstacles)) if self.obstacles else self.area

    def region(self, name: str) -> Region:
        try:
            return self.regions[name]
        except KeyError:
            available = ", ".join(self.regions) or "none"
            raise MapError(f"map {self.name} has no region {name!r}; its regions are: {available}") from None

    def regions_with_role(self, role: str) -> list[Region]:
        if role not in ROLES:
            raise MapError(f"there is no region role {role!r}; roles are {', '.join(ROLES)}")
        return [r for r in self.regions.values() if r.role == role]

    def obstacle_label(self, index: int) -> str:
        assert self.obstacle_names is not None  # filled in on construction
        name = self.obstacle_names[index]
        return f"{name!r}" if name else f"#{index}"

    def check_position(self, point, who: str) -> None:
        """Raise a MapError naming ``who`` unless ``point`` (metres) is in the free space."""
        try:
            x, y = (float(v) for v in point)
        except (TypeError, ValueError):
            raise MapError(f"{who} position {point!r} is not a pair of numbers (x, y)") from None
        if not (math.isfinite(x) and math.isfinite(y)):
            raise MapError(f"{who} at ({x}, {y}) has a coordinate that is not a finite number")
        where = f"{who} at ({x:.1f}, {y:.1f})"
        position = Point(x, y)
        if not self.area.covers(position):
            raise MapError(f"{where} is outside the area of map {self.name}")
        if self.free_space.covers(position):
            return
        index = next((i for i, o in enumerate(self.obstacles) if o.covers(position)), None)
        culprit = "an obstacle" if index is None else f"obstacle {self.obstacle_label(index)}"
        raise MapError(f"{where} is inside {culprit} of map {self.name}")

    def to_local(self, lat, lon):
        """East/north metres of WGS84 ``(lat, lon)`` degrees; vectorised."""
        return geodesy.to_local(lat, lon, self.origin)

    def to_geodetic(self, x, y):
        """WGS84 ``(lat, lon)`` degrees of local ``(x, y)`` metres; vectorised."""
        return geodesy.to_geodetic(x, y, self.origin)
