"""Maps: the playing area, obstacles, terrain zones and game regions, in local metres.

Load one with ``load_map(name_or_path)``, lay it on a grid with
``rasterize``. Files follow the schema in maps/SCHEMA.md.
"""

from bearcat.maps.catalog import list_maps, load_map
from bearcat.maps.errors import MapError
from bearcat.maps.geojson import read_geojson, write_geojson
from bearcat.maps.model import ROLES, Map, Region, Zone
from bearcat.maps.raster import Raster, rasterize

__all__ = [
    "ROLES",
    "Map",
    "MapError",
    "Raster",
    "Region",
    "Zone",
    "list_maps",
    "load_map",
    "rasterize",
    "read_geojson",
    "write_geojson",
]
