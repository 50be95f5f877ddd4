"""The map model, geodesy and the built-in maps."""

import math

import numpy as np
import pytest
import scipy.ndimage
import shapely
from shapely.geometry import Point, box

from bearcat.maps import ROLES, Map, MapError, Region, Zone, list_maps, load_map, rasterize

BUILT_IN = [
    "campus-200",
    "campus-250x200",
    "campus-400",
    "ctf-10",
    "field-50",
    "field-80x40",
    "maze-10",
    "maze-deadend-10",
    "square-10",
    "triangle-10",
]
ORIGIN = (37.8719, -122.2585)


def small_map(**overrides) -> Map:
    fields = dict(
        name="test",
        area=box(0, 0, 10, 10),
        origin=ORIGIN,
        obstacles=(box(2, 2, 4, 4),),
        obstacle_names=("library",),
        regions={"flag": Region("flag", "flag", Point(8, 8).buffer(1))},
    )
    fields.update(overrides)
    return Map(**fields)


# --- geodesy ---------------------------------------------------------------


def test_geodetic_round_trip_within_a_micrometre():
    m = small_map()
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-2000, 2000, (2, 500))
    lat, lon = m.to_geodetic(x, y)
    back_x, back_y = m.to_local(lat, lon)
    assert np.max(np.hypot(back_x - x, back_y - y)) < 1e-6


def test_known_distances_near_berkeley():
    m = small_map()
    lat0, lon0 = ORIGIN
    x, y = m.to_local(lat0 + 0.001, lon0)
    assert abs(x) < 1e-6 and y == pytest.approx(110.99, abs=0.1)
    x, y = m.to_local(lat0, lon0 + 0.001)
    # East: the parallel's radius, N cos(lat), with N the WGS84 prime-vertical radius.
    a, e2 = 6378137.0, 6.69437999014e-3
    parallel = a / math.sqrt(1 - e2 * math.sin(math.radians(lat0)) ** 2) * math.cos(math.radians(lat0))
    assert x == pytest.approx(parallel * math.radians(0.001), abs=0.01) and abs(y) < 0.01


def test_origin_maps_to_zero_and_scalars_stay_scalars():
    m = small_map()
    x, y = m.to_local(*ORIGIN)
    assert isinstance(x, float) and abs(x) < 1e-9 and abs(y) < 1e-9
    lat, lon = m.to_geodetic(np.zeros((3, 2)), np.zeros((3, 2)))
    assert lat.shape == (3, 2) and np.allclose(lat, ORIGIN[0]) and np.allclose(lon, ORIGIN[1])


def test_one_point_converts_to_the_same_numbers_as_an_array_of_them():
    m = small_map()
    rng = np.random.default_rng(2)
    x, y = rng.uniform(-2000, 2000, (2, 200))
    lat, lon = m.to_geodetic(x, y)
    east, north = m.to_local(lat, lon)
    for k in range(len(x)):
        assert m.to_geodetic(x[k], y[k]) == (lat[k], lon[k])
        assert m.to_local(float(lat[k]), np.float64(lon[k])) == (east[k], north[k])
    assert all(isinstance(v, float) for v in m.to_geodetic(np.array(1.0), 2.0))


# --- model -----------------------------------------------------------------


def test_bounds_free_space_and_region_lookup():
    m = small_map()
    assert m.bounds == (0.0, 0.0, 10.0, 10.0)
    assert m.free_space.area == pytest.approx(100 - 4)
    assert m.region("flag").role == "flag"
    assert m.regions_with_role("flag") == [m.regions["flag"]]
    assert m.regions_with_role("return") == []


def test_unknown_region_names_the_map_and_lists_regions():
    with pytest.raises(MapError, match=r"map test has no region 'home'; its regions are: flag"):
        small_map().region("home")


def test_unknown_role_lists_roles():
    with pytest.raises(MapError, match="roles are " + ", ".join(ROLES)):
        small_map().regions_with_role("base")


@pytest.mark.parametrize(
    ("point", "message"),
    [
        ((3.0, 3.0), r"attacker at \(3.0, 3.0\) is inside obstacle 'library' of map test"),
        ((12.0, 4.0), r"attacker at \(12.0, 4.0\) is outside the area of map test"),
        ((float("nan"), 4.0), r"attacker at \(nan, 4.0\) has a coordinate that is not a finite number"),
        ((1.0, float("inf")), "not a finite number"),
        ("here", "attacker position 'here' is not a pair of numbers"),
    ],
)
def test_check_position_names_who_and_why(point, message):
    with pytest.raises(MapError, match=message):
        small_map().check_position(point, "attacker")


def test_check_position_names_unnamed_obstacles_by_index():
    m = small_map(obstacles=(box(6, 0, 7, 1), box(2, 2, 4, 4)), obstacle_names=None)
    with pytest.raises(MapError, match="inside obstacle #1 of map test"):
        m.check_position((3, 3), "defender 2")


@pytest.mark.parametrize("point", [(0, 0), (10, 5), (2, 3), (4, 4), (5, 5)])
def test_boundaries_and_obstacle_edges_are_valid_positions(point):
    small_map().check_position(point, "attacker")


@pytest.mark.parametrize("speed", [0, 1.5, -0.2, float("nan"), "fast", True])
def test_zone_speed_must_be_in_unit_interval(speed):
    with pytest.raises(MapError, match=r"speed of zone 'lawn' must be a number in \(0, 1\]"):
        Zone("lawn", box(0, 0, 1, 1), speed)


def test_map_rejects_bad_parts():
    with pytest.raises(MapError, match="role 'base'"):
        Region("flag", "base", box(0, 0, 1, 1))
    with pytest.raises(MapError, match="region 'flag' of map test lies entirely outside its free space"):
        small_map(regions={"flag": Region("flag", "flag", box(2.5, 2.5, 3.5, 3.5))})
    with pytest.raises(MapError, match="area of map test is not a valid polygon"):
        small_map(area=shapely.Polygon([(0, 0), (10, 10), (10, 0), (0, 10)]))
    with pytest.raises(MapError, match="origin"):
        small_map(origin=(95.0, 0.0))
    with pytest.raises(MapError, match="1 obstacles but 2 obstacle names"):
        small_map(obstacle_names=("a", "b"))


# --- catalog ---------------------------------------------------------------


def test_list_maps_is_sorted_and_complete():
    assert list_maps() == BUILT_IN


def test_unknown_name_lists_the_built_in_maps():
    with pytest.raises(
        MapError, match="no built-in map 'campus-500'; the built-in maps are campus-200, campus-250x200, campus-400"
    ):
        load_map("campus-500")


def test_missing_file_is_named(tmp_path):
    path = tmp_path / "nowhere.geojson"
    with pytest.raises(MapError, match=f"map file {path} does not exist"):
        load_map(str(path))
    with pytest.raises(MapError, match="does not exist"):
        load_map(path)


# --- built-in maps ----------------------------------------------------------


@pytest.fixture(scope="module", params=BUILT_IN)
def built_in(request):
    return load_map(request.param)


def test_built_in_geometry_is_valid(built_in):
    m = built_in
    assert m.area.is_valid and all(o.is_valid for o in m.obstacles)
    assert all(z.geometry.is_valid and 0 < z.speed <= 1 for z in m.zones)
    assert m.description and m.name in BUILT_IN
    lat, lon = m.origin
    assert abs(lat - 37.8719) < 0.01 and abs(lon + 122.2585) < 0.01


def test_built_in_regions_lie_in_the_free_space(built_in):
    for region in built_in.regions.values():
        assert built_in.area.covers(region.geometry), region.name
        assert region.geometry.intersection(built_in.free_space).area == pytest.approx(region.geometry.area)


def test_built_in_free_space_is_connected(built_in):
    m = built_in
    assert m.free_space.geom_type == "Polygon"
    width = m.bounds[2] - m.bounds[0]
    raster = rasterize(m, 0.1 if width <= 10 else 1.0)
    # 4-connectivity, as fast marching sees the grid.
    _, components = scipy.ndimage.label(raster.free)
    assert components == 1


EXPECTED_REGIONS = {
    "ctf-10": {"home": "return", "flag": "flag"},
    "field-50": {"home": "return", "flag": "flag"},
    "campus-200": {"flag": "flag", "home": "return"},
    "campus-250x200": {"flag": "flag", "home": "return"},
    "campus-400": {"flag": "flag", "home": "return"},
    "field-80x40": {"west": "side", "east": "side"},
    "square-10": {},
    "triangle-10": {},
    "maze-10": {},
    "maze-deadend-10": {},
}


def test_built_in_regions_and_roles(built_in):
    assert {n: r.role for n, r in built_in.regions.items()} == EXPECTED_REGIONS[built_in.name]


def test_field_50_matches_the_thesis():
    m = load_map("field-50")
    assert m.bounds == (0, 0, 50, 50) and not m.obstacles
    assert m.region("home").geometry.equals(box(0, 45, 50, 50))
    flag = m.region("flag").geometry
    assert flag.centroid.distance(Point(25, 15)) < 1e-9
    assert flag.area == pytest.approx(math.pi * 2.5**2, rel=1e-3)


def test_campus_200_hall_blocks_the_straight_run_home():
    m = load_map("campus-200")
    width, height = m.bounds[2] - m.bounds[0], m.bounds[3] - m.bounds[1]
    assert (width, height) == (200, 180)
    flag = m.region("flag").geometry.centroid
    run = shapely.LineString([flag, (flag.x, m.bounds[3])])
    blockers = [n for o, n in zip(m.obstacles, m.obstacle_names) if o.intersects(run)]
    assert blockers == ["hall"]
    assert 5 <= len(m.obstacles) <= 7


def test_campus_400_has_walkways_and_far_apart_targets():
    m = load_map("campus-400")
    assert m.bounds == (0, 0, 400, 400) and 8 <= len(m.obstacles) <= 14
    assert m.area_speed == pytest.approx(0.6)
    speeds = {z.speed for z in m.zones}
    assert 1.0 in speeds and any(0 < s < 1 for s in speeds)
    flag, home = m.region("flag").geometry, m.region("home").geometry
    assert flag.distance(home) > 200
    walkways = shapely.union_all([z.geometry for z in m.zones if z.speed == 1])
    assert walkways.geom_type == "Polygon", "the walkway network is one piece"
    assert walkways.intersects(flag) and walkways.intersects(home)
    m.check_position((40, 40), "attacker")
    m.check_position((200, 200), "defender")
    # Where walkways run between buildings there is room on both sides.
    for obstacle, name in zip(m.obstacles, m.obstacle_names):
        assert obstacle.distance(walkways) >= 3, name


def test_field_80x40_has_team_sides():
    m = load_map("field-80x40")
    assert m.bounds == (0, 0, 80, 40)
    assert (m.region("west").team, m.region("east").team) == ("pursuers", "evader")


@pytest.mark.parametrize("name", ["maze-10", "maze-deadend-10"])
def test_maze_corridors_are_about_a_capture_diameter_wide(name):
    free = load_map(name).free_space
    # A disk of 0.49 m radius passes everywhere; one of 0.8 m is stuck in parts of the maze.
    assert free.buffer(-0.49).geom_type == "Polygon"
    assert free.buffer(-0.8).geom_type == "MultiPolygon"


def test_every_maze_10_corridor_lies_on_a_loop_and_the_dead_end_maze_has_none():
    # Free-standing walls are holes in the free space: a path can go round each.
    assert len(load_map("maze-10").free_space.interiors) == 4
    assert len(load_map("maze-deadend-10").free_space.interiors) == 0
