"""Rasterisation: node classes agree with the geometry, boundaries follow the closed-set rules."""

import numpy as np
import pytest
import shapely
from shapely.geometry import Point, Polygon, box

from bearcat.maps import Map, MapError, Region, Zone, list_maps, load_map, rasterize
from bearcat.maps.raster import MAX_NODES
from bearcat.maps.scanline import TOLERANCE, coverage
from bearcat.solvers.grid import Grid

ORIGIN = (37.8719, -122.2585)


def spacing_for(m: Map) -> float:
    return 0.1 if m.bounds[2] - m.bounds[0] <= 10 else 0.5


def assert_area(count: int, grid: Grid, geometry) -> None:
    """Nodes times cell area approximate an area up to a band of one spacing along the boundary."""
    h = grid.spacing[0]
    band = geometry.boundary.length * h + 4 * h * h
    assert abs(count * grid.cell_area - geometry.area) <= band, (count * grid.cell_area, geometry.area, band)


@pytest.fixture(scope="module", params=list_maps())
def laid(request):
    m = load_map(request.param)
    return m, rasterize(m, spacing_for(m))


def test_free_nodes_measure_the_free_space(laid):
    m, r = laid
    assert r.speed.shape == r.grid.shape and r.speed.dtype == np.float64
    assert_area(int(r.free.sum()), r.grid, m.free_space)


def test_obstacle_nodes_measure_the_obstacles(laid):
    m, r = laid
    in_area = rasterize(Map(m.name, m.area, m.origin), grid=r.grid).free
    blocked = shapely.union_all(m.obstacles).intersection(m.area) if m.obstacles else Polygon()
    assert_area(int((in_area & ~r.free).sum()), r.grid, blocked)


def test_region_masks_measure_the_regions(laid):
    m, r = laid
    assert set(r.masks) == set(m.regions)
    for name, region in m.regions.items():
        mask = r.masks[name]
        assert mask.dtype == bool and not (mask & ~r.free).any()
        assert_area(int(mask.sum()), r.grid, region.geometry.intersection(m.free_space))


def test_speed_classes_measure_the_painted_zones(laid):
    m, r = laid
    painted = {m.area_speed: [m.area.difference(shapely.union_all([z.geometry for z in m.zones]))]}
    for k, zone in enumerate(m.zones):
        later = shapely.union_all([z.geometry for z in m.zones[k + 1 :]])
        painted.setdefault(zone.speed, []).append(zone.geometry.difference(later))
    for speed, parts in painted.items():
        expected = shapely.union_all(parts).intersection(m.free_space)
        assert_area(int((r.speed == speed).sum()), r.grid, expected)
    assert set(np.unique(r.speed)) <= set(painted) | {0.0}


def square_map(**overrides) -> Map:
    fields = dict(name="square", area=box(0, 0, 10, 10), origin=ORIGIN, obstacles=(box(2, 2, 4, 4),), area_speed=0.5)
    fields.update(overrides)
    return Map(**fields)


def test_area_boundary_and_obstacle_edges_are_free_obstacle_interior_is_not():
    r = rasterize(square_map(), 1.0)
    assert r.grid.shape == (11, 11)
    speed = r.speed
    for node in [(0, 0), (10, 10), (0, 7), (10, 3), (7, 0)]:
        assert speed[node] == 0.5, node
    for node in [(2, 2), (2, 3), (4, 4), (3, 4), (3, 2)]:
        assert speed[node] == 0.5, node
    assert speed[3, 3] == 0


def test_edges_on_round_coordinates_survive_floating_point_node_positions():
    # Nodes at k * 0.1 miss 0.3 and 0.7 by a few 1e-17 m; they still lie on the edges.
    m = square_map(area=box(0, 0, 1, 1), obstacles=(box(0.3, 0.3, 0.7, 0.7),))
    r = rasterize(m, 0.1)
    xs, _ys = r.grid.axes()
    assert xs[3] != 0.3 or xs[7] != 0.7
    blocked = ~r.free
    assert blocked[4:7, 4:7].all()
    assert blocked.sum() == 9
    assert r.free[:, 0].all() and r.free[:, -1].all() and r.free[0, :].all() and r.free[-1, :].all()


def test_abutting_obstacles_leave_no_seam():
    m = square_map(obstacles=(box(2, 2, 4, 4), box(4, 2, 6, 4)))
    r = rasterize(m, 1.0)
    assert r.speed[4, 3] == 0
    assert r.speed[4, 2] > 0 and r.speed[4, 4] > 0


def test_zones_are_painted_in_order_over_the_area_speed():
    west, east = box(0, 0, 6, 10), box(4, 0, 10, 10)
    first = rasterize(square_map(obstacles=(), zones=(Zone("w", west, 0.2), Zone("e", east, 0.8))), 1.0)
    second = rasterize(square_map(obstacles=(), zones=(Zone("e", east, 0.8), Zone("w", west, 0.2))), 1.0)
    assert first.speed[5, 5] == 0.8 and second.speed[5, 5] == 0.2
    assert first.speed[1, 5] == second.speed[1, 5] == 0.2
    assert first.speed[9, 5] == second.speed[9, 5] == 0.8
    patch = rasterize(square_map(obstacles=(), zones=(Zone("p", box(1, 1, 2, 2), 1.0),)), 0.5)
    assert patch.speed[0, 0] == 0.5 and patch.speed[3, 3] == 1.0
    assert (patch.speed == 1.0).sum() == 9


def test_obstacles_override_zones_and_nothing_moves_outside_the_area():
    triangle = Polygon([(0, 0), (10, 0), (0, 10)])
    m = square_map(area=triangle, obstacles=(box(1, 1, 3, 3),), zones=(Zone("all", box(-5, -5, 15, 15), 0.9),))
    r = rasterize(m, grid=Grid.covering((-2, -2), (12, 12), 0.5))
    x, y = r.grid.mesh()
    outside = ~shapely.intersects_xy(triangle, x, y)
    assert (r.speed[outside] == 0).all()
    assert r.speed[(x == 2) & (y == 2)] == 0
    assert r.speed[(x == 5) & (y == 5)] == 0.9
    assert r.speed[(x == 6) & (y == 2)] == 0.9


def test_region_masks_leave_out_obstacle_nodes():
    region = Region("yard", "target", box(1, 1, 5, 5))
    r = rasterize(square_map(regions={"yard": region}), 1.0)
    assert r.masks["yard"].sum() == 25 - 1
    assert not r.masks["yard"][3, 3]


def test_grid_argument_and_spacing_argument_agree():
    m = load_map("triangle-10")
    by_spacing = rasterize(m, 0.25)
    by_grid = rasterize(m, grid=Grid.covering((0, 0), (10, 10), 0.25))
    assert by_spacing.grid == by_grid.grid and np.array_equal(by_spacing.speed, by_grid.speed)


def test_a_window_of_the_map_matches_the_whole():
    m = load_map("campus-400")
    whole = rasterize(m, 1.0)
    window = rasterize(m, grid=Grid.covering((150, 180), (230, 260), 1.0))
    assert np.array_equal(window.speed, whole.speed[150:231, 180:261])
    assert np.array_equal(window.masks["flag"], whole.masks["flag"][150:231, 180:261])


def test_bad_raster_requests():
    m = load_map("square-10")
    with pytest.raises(TypeError):
        rasterize(m)
    with pytest.raises(TypeError):
        rasterize(m, 1.0, grid=Grid.covering((0, 0), (10, 10), 1.0))
    with pytest.raises(MapError, match=f"too large.*limit {MAX_NODES:,}"):
        rasterize(m, 1e-4)


def test_scanline_matches_shapely_on_random_polygons_with_holes():
    rng = np.random.default_rng(7)
    xs, ys = np.arange(-1, 11, 0.1), np.arange(-1, 11, 0.13)
    x, y = np.meshgrid(xs, ys, indexing="ij")
    points = shapely.points(x, y)
    checked = 0
    for k in range(60):
        shape = shapely.make_valid(Polygon(rng.uniform(0, 10, (7, 2)))).buffer(0)
        if k % 2:
            shape = shape.difference(Point(rng.uniform(2, 8, 2)).buffer(1.5))
        if shape.geom_type not in ("Polygon", "MultiPolygon"):
            continue
        found = coverage(shape, xs, ys)
        covers, boundary = np.zeros(x.shape, bool), np.zeros(x.shape, bool)
        covers[found.window], boundary[found.window] = found.covers, found.boundary
        near = shapely.distance(shape.boundary, points) <= TOLERANCE
        assert np.array_equal(boundary, near)
        assert np.array_equal(covers[~near], shapely.intersects_xy(shape, x, y)[~near])
        checked += 1
    assert checked > 40
