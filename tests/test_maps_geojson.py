"""GeoJSON reading and writing: round trips, user-drawn files, and errors that name the culprit."""

import json
import math
import re
from pathlib import Path

import pytest
import shapely
from shapely.geometry import box

from bearcat import maps
from bearcat.maps import MapError, list_maps, load_map, read_geojson, write_geojson
from bearcat.maps.geodesy import to_geodetic
from bearcat.maps.geojson import parse_geojson

ORIGIN = {"lat": 37.8719, "lon": -122.2585}


def geometries(m):
    yield "area", m.area
    yield from (("obstacle", o) for o in m.obstacles)
    yield from ((f"zone {z.name}", z.geometry) for z in m.zones)
    yield from ((f"region {r.name}", r.geometry) for r in m.regions.values())


def assert_same_map(a, b, tolerance):
    assert (a.name, a.description, a.origin, a.area_speed) == (b.name, b.description, b.origin, b.area_speed)
    assert a.obstacle_names == b.obstacle_names
    assert [(z.name, z.speed) for z in a.zones] == [(z.name, z.speed) for z in b.zones]
    regions = [[(r.name, r.role, r.team) for r in m.regions.values()] for m in (a, b)]
    assert regions[0] == regions[1]
    pairs = list(zip(geometries(a), geometries(b), strict=True))
    for (what, g), (_, h) in pairs:
        if tolerance == 0:
            assert g.normalize().equals_exact(h.normalize(), 0), what
        else:
            assert shapely.hausdorff_distance(g, h) < tolerance, what


@pytest.mark.parametrize("name", list_maps())
@pytest.mark.parametrize(("units", "tolerance"), [("metres", 0), ("degrees", 1e-6)])
def test_round_trip(tmp_path, name, units, tolerance):
    original = load_map(name)
    path = tmp_path / f"{name}.geojson"
    write_geojson(original, path, units=units)
    assert json.loads(path.read_text())["bearcat"]["units"] == units
    assert_same_map(original, read_geojson(path), tolerance)


def test_written_degrees_are_lon_lat_with_counterclockwise_shells(tmp_path):
    path = tmp_path / "field.geojson"
    write_geojson(load_map("field-50"), path)
    area = json.loads(path.read_text())["features"][0]
    assert area["properties"] == {"kind": "area"}
    ring = area["geometry"]["coordinates"][0]
    lon, lat = ring[0]
    assert -122.3 < lon < -122.2 and 37.8 < lat < 37.9
    assert shapely.LinearRing(ring).is_ccw


def feature(kind, geometry, **props):
    return {"type": "Feature", "properties": {"kind": kind, **props}, "geometry": geometry}


def polygon(x0, y0, x1, y1):
    return shapely.geometry.mapping(box(x0, y0, x1, y1))


def write(tmp_path, features, units="metres", **meta):
    meta = {"origin": ORIGIN, "units": units, **meta}
    path = tmp_path / "drawn.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "bearcat": meta, "features": features}))
    return path


def test_drawing_primitives_become_polygons(tmp_path):
    path = write(
        tmp_path,
        [
            feature("area", polygon(0, 0, 100, 50), speed=0.5),
            feature("zone", {"type": "LineString", "coordinates": [[0, 25], [100, 25]]}, speed=1, width=4),
            feature(
                "obstacle",
                {
                    "type": "MultiPolygon",
                    "coordinates": [polygon(10, 30, 20, 40)["coordinates"], polygon(30, 30, 40, 40)["coordinates"]],
                },
                name="twins",
            ),
            feature("region", {"type": "Point", "coordinates": [80, 10]}, name="flag", role="flag", radius=3),
            feature("region", polygon(0, 0, 10, 50), name="west", role="side", team="red"),
        ],
        name="drawn field",
    )
    m = read_geojson(path)
    assert m.name == "drawn field" and m.description == "" and m.area_speed == 0.5
    walkway = m.zones[0].geometry
    assert walkway.equals(box(0, 23, 100, 27)), "flat caps, width in metres"
    assert m.obstacle_names == ("twins", "twins") and len(m.obstacles) == 2
    assert m.region("flag").geometry.area == pytest.approx(math.pi * 9, rel=1e-3)
    assert m.region("west").team == "red"


def test_a_file_drawn_in_degrees_without_origin(tmp_path):
    lon0, lat0 = -122.26, 37.87
    square = [[lon0, lat0], [lon0 + 0.001, lat0], [lon0 + 0.001, lat0 + 0.001], [lon0, lat0 + 0.001], [lon0, lat0]]
    path = tmp_path / "my-field.geojson"
    path.write_text(
        json.dumps(
            {
                "type": "FeatureCollection",
                "features": [
                    feature("area", {"type": "Polygon", "coordinates": [square]}),
                ],
            }
        )
    )
    m = load_map(str(path))
    assert m.name == "my-field" and m.origin == (lat0, lon0)
    xmin, ymin, xmax, ymax = m.bounds
    assert abs(xmin) < 1e-3 and abs(ymin) < 1e-6
    assert ymax == pytest.approx(110.99, abs=0.1) and xmax == pytest.approx(87.9, abs=0.2)


def test_degrees_file_keeps_its_origin(tmp_path):
    lat, lon = to_geodetic(25.0, 10.0, (ORIGIN["lat"], ORIGIN["lon"]))
    corner = [ORIGIN["lon"], ORIGIN["lat"]]
    triangle = [corner, [lon + 0.001, corner[1]], [lon + 0.001, lat + 0.001], corner]
    path = write(
        tmp_path,
        [
            feature("area", {"type": "Polygon", "coordinates": [triangle]}),
            feature("region", {"type": "Point", "coordinates": [lon, lat]}, name="flag", role="flag", radius=1),
        ],
        units="degrees",
    )
    centre = read_geojson(path).region("flag").geometry.centroid
    assert centre.distance(shapely.Point(25, 10)) < 1e-3


AREA = feature("area", polygon(0, 0, 50, 50))
SQUARE = polygon(1, 1, 2, 2)
POINT = {"type": "Point", "coordinates": [1, 1]}
LINE = {"type": "LineString", "coordinates": [[0, 1], [9, 1]]}
BOWTIE = {"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]}
UNCLOSED = {"type": "Polygon", "coordinates": [[[0, 0], [1, 1]]]}
DEGREES_HINT = r'; .*"units": "metres"'
ZONE, REGION, OBSTACLE = r"feature 1 \(zone\): ", r"feature 1 \(region\): ", r"feature 1 \(obstacle\)"
MALFORMED = [
    (
        [AREA, feature("lake", SQUARE)],
        {},
        "feature 1: property 'kind': 'lake' is not one of 'area', 'obstacle', 'zone', 'region'",
    ),
    ([feature("obstacle", SQUARE)], {}, "must have exactly one feature of kind 'area', found none"),
    ([AREA, AREA], {}, "exactly one feature of kind 'area', found features 0, 1"),
    ([AREA, feature("zone", SQUARE, speed=0)], {}, ZONE + r"property 'speed': must be a number in \(0, 1\], got 0"),
    ([AREA, feature("zone", SQUARE, speed=1.5)], {}, ZONE + "property 'speed': .* got 1.5"),
    ([AREA, feature("zone", SQUARE)], {}, ZONE + r"property 'speed': must be given, as a number in \(0, 1\]"),
    (
        [AREA, feature("zone", SQUARE, speed=1, name="")],
        {},
        ZONE + "property 'name': must be a non-empty string, got ''",
    ),
    (
        [AREA, feature("zone", LINE, speed=1, width=-2)],
        {},
        ZONE + r"property 'width': must be a number in \(0, 10000\] m",
    ),
    (
        [AREA, feature("zone", LINE, speed=1)],
        {},
        ZONE + r"property 'width': must be given for a LineString, as a number in \(0, 10000\] m",
    ),
    (
        [
            AREA,
            feature("region", SQUARE, name="flag", role="flag"),
            feature("region", SQUARE, name="flag", role="return"),
        ],
        {},
        r"feature 2 \(region\): property 'name' repeats region name 'flag'",
    ),
    (
        [AREA, feature("region", SQUARE, role="flag")],
        {},
        REGION + "property 'name': must be given, as a non-empty string",
    ),
    (
        [AREA, feature("region", SQUARE, name="f", role="base")],
        {},
        REGION + "property 'role': 'base' is not one of 'flag', 'return', 'side', 'target'",
    ),
    (
        [AREA, feature("region", POINT, name="f", role="flag")],
        {},
        REGION + "property 'radius': must be given for a Point, as a number in",
    ),
    ([AREA, feature("obstacle", POINT)], {}, OBSTACLE + ": geometry must be one of Polygon, MultiPolygon; got Point"),
    ([AREA, feature("obstacle", BOWTIE)], {}, OBSTACLE + r": geometry is not a valid polygon \(Self-intersection"),
    ([AREA, feature("obstacle", UNCLOSED)], {}, OBSTACLE + ": geometry is not valid GeoJSON"),
    ([AREA, feature("obstacle", None)], {}, OBSTACLE + " has no geometry"),
    (
        [AREA, feature("region", polygon(60, 60, 70, 70), name="far", role="flag")],
        {},
        "region 'far' of map drawn lies entirely outside its free space",
    ),
    ([AREA], {"units": "feet"}, "bearcat.units must be 'degrees' or 'metres', got 'feet'"),
    ([AREA], {"origin": None}, "a map in metres needs bearcat.origin"),
    ([AREA], {"origin": {"lat": 123, "lon": 0}}, r"origin \(123.0, 0.0\) is not a latitude"),
    ([AREA], {"name": ""}, "bearcat.name must be a non-empty string"),
    ([AREA], {"units": "degrees"}, r"feature 0 \(area\): the area spans more than 0.5 degrees" + DEGREES_HINT),
    (
        [feature("area", polygon(0, 0, 400, 400))],
        {"units": "degrees"},
        r"feature 0 \(area\): coordinates are not longitude/latitude in degrees" + DEGREES_HINT,
    ),
    (["oops"], {}, "feature 0 is not a GeoJSON Feature"),
]


@pytest.mark.parametrize(("features", "meta", "message"), MALFORMED)
def test_malformed_files_name_the_culprit(tmp_path, features, meta, message):
    meta = {"origin": ORIGIN, "units": "metres", **meta}
    meta = {k: v for k, v in meta.items() if v is not None}
    path = tmp_path / "drawn.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "bearcat": meta, "features": features}))
    with pytest.raises(MapError, match=message) as caught:
        read_geojson(path)
    assert str(caught.value).startswith(f"map file {path}")
    assert "\n" not in str(caught.value)


def test_invalid_json_names_file_and_position(tmp_path):
    path = tmp_path / "broken.geojson"
    path.write_text('{"type": "FeatureCollection", "features": [}')
    with pytest.raises(MapError, match=f"map file {path} is not valid JSON .*line 1, column"):
        load_map(path)


def test_a_file_nested_too_deeply_is_named(tmp_path):
    path = tmp_path / "deep.geojson"
    path.write_text('{"type": "FeatureCollection", "features": ' + "[" * 100_000 + "]" * 100_000 + "}")
    with pytest.raises(MapError, match=f"map file {path} nests arrays or objects too deeply to be a map"):
        load_map(path)


def test_not_a_feature_collection(tmp_path):
    path = tmp_path / "point.json"
    path.write_text('{"type": "Point", "coordinates": [0, 0]}')
    with pytest.raises(MapError, match="is not a GeoJSON FeatureCollection"):
        load_map(str(path))


def test_a_directory_is_not_a_map(tmp_path):
    with pytest.raises(MapError, match="cannot be read"):
        read_geojson(tmp_path)


def test_the_schema_example_reads():
    schema = (Path(maps.__file__).parent / "SCHEMA.md").read_text()
    example = re.search(r"```json\n(.*?)```", schema, re.S).group(1)
    m = parse_geojson(example, source="SCHEMA.md", default_name="example")
    assert m.name == "my-field" and m.bounds == (0, 0, 120, 80)
    assert list(m.regions) == ["flag", "home"] and m.obstacle_names == ("shed",)
