"""Maps by name: the built-in ones shipped in maps/data, or any GeoJSON file."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from bearcat.maps.errors import MapError
from bearcat.maps.geojson import parse_geojson, read_geojson
from bearcat.maps.model import Map

SUFFIX = ".geojson"


def _data():
    return resources.files("bearcat.maps") / "data"


def list_maps() -> list[str]:
    """Names of the built-in maps, sorted."""
    return sorted(p.name[: -len(SUFFIX)] for p in _data().iterdir() if p.name.endswith(SUFFIX))


def load_map(name_or_path: str | Path) -> Map:
    """A built-in map by name, or the map in a GeoJSON file.

    A string that names a built-in map wins over a file of the same name in
    the working directory, so scenarios mean the same thing wherever they run.
    """
    if isinstance(name_or_path, str) and name_or_path in list_maps():
        text = (_data() / f"{name_or_path}{SUFFIX}").read_text(encoding="utf-8")
        return parse_geojson(text, source=f"built-in map {name_or_path}", default_name=name_or_path)
    path = Path(name_or_path)
    if isinstance(name_or_path, Path) or path.exists() or path.suffix in (SUFFIX, ".json") or len(path.parts) > 1:
        return read_geojson(path)
    raise MapError(
        f"there is no built-in map {name_or_path!r}; the built-in maps are {', '.join(list_maps())}, "
        "or give the path of a .geojson file"
    )
