"""Fast marching against analytic travel times, capture min-filter, path descent, bilinear reads."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from bearcat.solvers.errors import InputError
from bearcat.solvers.grid import Grid
from bearcat.solvers.interpolation import bilinear
from bearcat.solvers.marching.descent import descend, descend_steps
from bearcat.solvers.marching.fmm import point_source, time_to_capture, travel_time


def square(n, side=10.0):
    return Grid.spanning((0.0, 0.0), (side, side), (n, n))


def max_error_from_point(n, order, speed=2.0, source=(3.37, 4.21)):
    g = square(n)
    v = np.full(g.shape, speed)
    phi = travel_time(v, g.spacing, point_source(g, source, v), order=order)
    x, y = g.mesh()
    return np.abs(phi - np.hypot(x - source[0], y - source[1]) / speed).max()


def test_constant_speed_point_source_converges_at_first_order():
    errors = [max_error_from_point(n, 1) for n in (41, 81, 161)]
    h, speed = 10.0 / 40, 2.0
    assert errors[0] < 1.5 * h / speed  # distance / speed within O(h)
    assert errors[1] < 0.65 * errors[0]
    assert errors[2] < 0.65 * errors[1]


def disk_seeded_errors(order, sizes=(41, 81, 161)):
    """Seed exact times on a disk so the solution is smooth where it is computed."""
    out = []
    for n in sizes:
        g = square(n)
        x, y = g.mesh()
        d = np.hypot(x - 3.37, y - 4.21)
        exact = d / 2.0
        phi = travel_time(np.full(g.shape, 2.0), g.spacing, np.where(d <= 1.0, exact, np.inf), order=order)
        out.append(np.abs(phi - exact).max())
    return np.array(out)


def test_first_and_second_order_convergence_rates_on_a_smooth_front():
    first = disk_seeded_errors(1)
    second = disk_seeded_errors(2)
    rate1 = np.log2(first[:-1] / first[1:])
    rate2 = np.log2(second[:-1] / second[1:])
    assert np.all((rate1 > 0.85) & (rate1 < 1.3))
    assert np.all(rate2 > 1.8)
    assert second[-1] < 0.1 * first[-1]


def test_second_order_is_more_accurate_from_a_point_source():
    assert max_error_from_point(161, 2) < 0.5 * max_error_from_point(161, 1)


def test_anisotropic_spacing():
    g = Grid.spanning((0.0, 0.0), (10.0, 6.0), (101, 121))
    v = np.full(g.shape, 1.5)
    src = (4.1, 2.9)
    phi = travel_time(v, g.spacing, point_source(g, src, v))
    x, y = g.mesh()
    assert np.abs(phi - np.hypot(x - src[0], y - src[1]) / 1.5).max() < 0.03 * 10 / 1.5


def test_plane_wave_through_a_slow_slab_is_the_one_dimensional_sum():
    g = Grid.spanning((0.0, 0.0), (20.0, 5.0), (81, 21))
    h = g.spacing[0]
    x, _ = g.mesh()
    v = np.where((x > 7.1) & (x < 12.1), 0.5, 2.0)
    initial = np.where(x == 0.0, 0.0, np.inf)
    phi = travel_time(v, h, initial)
    expected = np.cumsum(h / v[:, 0]) - h / v[0, 0]
    np.testing.assert_allclose(phi, np.broadcast_to(expected[:, None], phi.shape), rtol=1e-12)
    # And against the continuous slab: the interface is between nodes.
    analytic = np.minimum(x, 7.1) / 2 + np.clip(x - 7.1, 0, 5) / 0.5 + np.clip(x - 12.1, 0, None) / 2
    assert np.abs(phi - analytic).max() <= h * (1 / 0.5 - 1 / 2.0) + 1e-9


def test_two_zones_straight_paths_where_they_are_optimal():
    """Source in the fast half: the fast half is convex, so straight lines are
    optimal there; straight down across the interface is Snell at normal incidence."""
    g = Grid.spanning((0.0, 0.0), (20.0, 20.0), (161, 161))
    x, y = g.mesh()
    fast, slow = 3.0, 1.0
    v = np.where(y >= 8.0, fast, slow)
    src = (10.0, 14.0)
    phi = travel_time(v, g.spacing, point_source(g, src, v))
    upper = y >= 8.0
    straight = np.hypot(x - src[0], y - src[1]) / fast
    assert np.abs(phi - straight)[upper].max() < 0.02 * straight.max()
    below = g.nearest_index((10.0, 2.0))
    assert phi[below] == pytest.approx(6.0 / fast + 6.0 / slow, rel=0.02)
    # Nowhere is it faster than travelling at the top speed.
    assert np.all(phi >= straight - 1e-9)


def wall_geodesic(a, b, h):
    """Shortest path over the wall, grown by half a cell as the nodes see it."""
    top, left, right = 30 + h / 2, 20 - h / 2, 22 + h / 2
    return math.dist(a, (left, top)) + (right - left) + math.dist((right, top), b)


def wall_world(h=0.25):
    g = Grid.covering((0.0, 0.0), (50.0, 40.0), h)
    x, y = g.mesh()
    v = np.ones(g.shape)
    v[(x >= 20) & (x <= 22) & (y <= 30)] = 0.0
    return g, v


def test_travel_time_around_a_wall_matches_the_geodesic():
    g, v = wall_world()
    src, far = (10.0, 10.0), (35.0, 8.0)
    geodesic = wall_geodesic(src, far, g.spacing[0])
    for order, tolerance in ((1, 0.025), (2, 0.01)):
        phi = travel_time(v, g.spacing, point_source(g, src, v), order=order)
        assert phi[g.nearest_index(far)] == pytest.approx(geodesic, rel=tolerance)
    assert math.dist(src, far) < 0.75 * geodesic  # ignoring the wall would fail
    assert np.all(np.isinf(phi[v == 0]))


def test_enclosed_region_is_never_reached():
    g = square(41)
    x, y = g.mesh()
    v = np.ones(g.shape)
    ring = np.abs(np.hypot(x - 7, y - 7) - 2) < 0.4
    v[ring] = 0
    phi = travel_time(v, g.spacing, point_source(g, (2.0, 2.0), v))
    assert np.all(np.isinf(phi[np.hypot(x - 7, y - 7) < 1.5]))
    assert np.isfinite(phi[np.hypot(x - 7, y - 7) > 2.5]).all()


def test_point_source_seeds_exact_times_without_snapping():
    g = square(21)
    v = np.full(g.shape, 4.0)
    src = (3.3, 4.8)  # not on a node
    init = point_source(g, src, v)
    seeded = np.isfinite(init)
    x, y = g.mesh()
    exact = np.hypot(x - src[0], y - src[1]) / 4.0
    assert 4 <= seeded.sum() <= 16
    np.testing.assert_allclose(init[seeded], exact[seeded])
    phi = travel_time(v, g.spacing, init)
    np.testing.assert_allclose(phi[seeded], exact[seeded])


def test_seeds_join_the_band_and_can_be_improved():
    g = square(41)
    v = np.ones(g.shape)
    init = np.full(g.shape, np.inf)
    init[5, 20] = 0.0
    init[15, 20] = 100.0  # too late: the front from the first seed gets there sooner
    init[35, 5] = 0.5  # early enough to keep its own value
    phi = travel_time(v, g.spacing, init)
    assert phi[15, 20] == pytest.approx(10 * g.spacing[0])
    assert phi[35, 5] == 0.5


def test_ceiling_stops_the_front():
    g = square(41)
    x, _y = g.mesh()
    v = np.ones(g.shape)
    src = (2.0, 5.0)
    plain = travel_time(v, g.spacing, point_source(g, src, v))
    ceiling = np.where(np.abs(x - 5.0) < 0.3, 1.0, np.inf)  # a barrier reached only after 3 s
    capped = travel_time(v, g.spacing, point_source(g, src, v), ceiling=ceiling)
    assert np.all(np.isinf(capped[x > 5.5]))
    left = x < 4.5
    np.testing.assert_array_equal(capped[left], plain[left])
    # Nodes under the ceiling keep their times; the rest are cut.
    assert np.array_equal(np.isfinite(capped) & (x < 5.5), (plain < ceiling) & (x < 5.5))


def test_time_to_capture_is_the_disk_minimum():
    g = square(101)
    x, y = g.mesh()
    v = np.ones(g.shape)
    src = (5.0, 5.0)
    psi = travel_time(v, g.spacing, point_source(g, src, v), order=2)
    psi_c = time_to_capture(psi, g.spacing, 2.0)
    d = np.hypot(x - src[0], y - src[1])
    expected = np.maximum(d - 2.0, 0.0)
    assert np.abs(psi_c - expected).max() < 0.1
    np.testing.assert_array_equal(time_to_capture(psi, g.spacing, 0.0), psi)


def test_capture_disk_reaches_across_a_thin_wall():
    """The capture set is a Euclidean disk: a defender next to a wall captures
    through it, which ``psi - r / v`` would miss (psi is infinite in the wall)."""
    g = square(51)
    x, _y = g.mesh()
    v = np.ones(g.shape)
    v[(np.abs(x - 5.0) < 0.1)] = 0
    psi = travel_time(v, g.spacing, point_source(g, (4.4, 5.0), v))
    psi_c = time_to_capture(psi, g.spacing, 1.0)
    assert psi[g.nearest_index((5.4, 5.0))] == np.inf
    assert psi_c[g.nearest_index((5.4, 5.0))] == 0.0


@settings(max_examples=25, deadline=None)
@given(
    nx=st.integers(3, 12),
    ny=st.integers(3, 12),
    hx=st.floats(0.2, 2.0),
    hy=st.floats(0.2, 2.0),
    radius=st.floats(0.0, 5.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_time_to_capture_matches_brute_force(nx, ny, hx, hy, radius, seed):
    rng = np.random.default_rng(seed)
    psi = rng.random((nx, ny))
    psi[rng.random((nx, ny)) < 0.2] = np.inf
    got = time_to_capture(psi, (hx, hy), radius)
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    expected = np.empty_like(psi)
    for i in range(nx):
        for j in range(ny):
            near = np.hypot((ix - i) * hx, (iy - j) * hy) <= radius * (1 + 1e-12)
            expected[i, j] = psi[near].min()
    np.testing.assert_array_equal(got, expected)


def first_order_residual(phi, speed, hx, hy, seeds):
    """|phi - upwind update from strictly earlier neighbours| at every computed node."""
    p = np.pad(phi, 1, constant_values=np.inf)
    worst = 0.0
    for i, j in zip(*np.nonzero(np.isfinite(phi) & ~seeds)):
        c = phi[i, j]
        ax = min((v for v in (p[i, j + 1], p[i + 2, j + 1]) if v < c), default=np.inf)
        ay = min((v for v in (p[i + 1, j], p[i + 1, j + 2]) if v < c), default=np.inf)
        f = 1 / speed[i, j]
        cands = [a + f * h for a, h in ((ax, hx), (ay, hy)) if a < np.inf]
        if ax < np.inf and ay < np.inf:
            s = hx * hx + hy * hy
            disc = s * f * f - (ax - ay) ** 2
            if disc >= 0:
                r = (hy * hy * ax + hx * hx * ay + hx * hy * math.sqrt(disc)) / s
                if r >= max(ax, ay):
                    cands.append(r)
        worst = max(worst, min(abs(c - u) for u in cands))
    return worst


@settings(max_examples=30, deadline=None)
@given(
    n=st.integers(4, 14),
    hx=st.floats(0.3, 2.0),
    hy=st.floats(0.3, 2.0),
    blocked=st.floats(0.0, 0.4),
    seed=st.integers(0, 2**32 - 1),
)
def test_random_speed_maps_solve_the_discrete_eikonal_equation(n, hx, hy, blocked, seed):
    rng = np.random.default_rng(seed)
    speed = rng.uniform(0.2, 3.0, (n, n))
    speed[rng.random((n, n)) < blocked] = 0.0
    initial = np.full((n, n), np.inf)
    src = rng.integers(0, n, 2)
    speed[tuple(src)] = 1.0
    initial[tuple(src)] = 0.0
    phi = travel_time(speed, (hx, hy), initial)
    assert phi[tuple(src)] == 0.0
    assert np.all(np.isinf(phi[speed == 0]))
    assert first_order_residual(phi, speed, hx, hy, np.isfinite(initial)) < 1e-9
    # Reachability is 4-connectivity through passable nodes.
    labels, _ = ndimage.label(speed > 0)
    np.testing.assert_array_equal(np.isfinite(phi), labels == labels[tuple(src)])


def test_descend_to_a_point_source_is_straight_and_ends_on_it():
    g = square(81, side=20.0)
    v = np.full(g.shape, 2.0)
    src = (4.3, 5.9)
    phi = travel_time(v, g.spacing, point_source(g, src, v))
    d = descend(g, phi, (17.0, 15.0), source=src)
    assert d.reached
    np.testing.assert_array_equal(d.points[0], (17.0, 15.0))
    np.testing.assert_array_equal(d.points[-1], src)
    assert d.values[-1] == 0.0
    assert np.all(np.diff(d.values) < 0)
    steps = np.hypot(*np.diff(d.points, axis=0).T)
    assert steps.max() <= 2 * g.spacing[0]
    length = steps.sum()
    straight = math.dist(src, (17.0, 15.0))
    assert length == pytest.approx(straight, rel=0.01)
    # Every vertex lies close to the segment.
    a, b = np.asarray(src), np.asarray((17.0, 15.0))
    u = (b - a) / np.linalg.norm(b - a)
    rel = d.points - a
    off = np.abs(rel[:, 0] * u[1] - rel[:, 1] * u[0])
    assert off.max() < 0.3


def test_descend_goes_around_a_wall_without_entering_it():
    g, v = wall_world()
    src, far = (10.0, 10.0), (35.0, 8.0)
    phi = travel_time(v, g.spacing, point_source(g, src, v))
    d = descend(g, phi, far, source=src)
    assert d.reached
    idx = np.rint(g.fractional_index(d.points)).astype(int)
    assert np.all(v[idx[:, 0], idx[:, 1]] > 0)
    h = g.spacing[0]
    x, y = d.points.T
    assert not np.any((x > 20 + h / 2) & (x < 22 - h / 2) & (y < 30 - h / 2))
    length = np.hypot(*np.diff(d.points, axis=0).T).sum()
    assert length == pytest.approx(wall_geodesic(src, far, h), rel=0.02)
    assert d.values[0] == pytest.approx(length, rel=0.03)


def test_descend_stops_at_seeds():
    g = square(41)
    x, _y = g.mesh()
    v = np.ones(g.shape)
    seeds = x <= 1.0
    phi = travel_time(v, g.spacing, np.where(seeds, 0.0, np.inf))
    d = descend(g, phi, (8.0, 3.0), seeds=seeds)
    assert d.reached
    assert d.points[-1][0] == pytest.approx(1.0, abs=0.3)
    assert d.points[-1][1] == pytest.approx(3.0, abs=0.3)


def test_a_descent_cut_short_is_the_start_of_the_whole_one():
    g = square(41)
    x, _y = g.mesh()
    seeds = x <= 1.0
    phi = travel_time(np.ones(g.shape), g.spacing, np.where(seeds, 0.0, np.inf))
    whole = descend(g, phi, (8.0, 3.0), seeds=seeds)
    start = descend(g, phi, (8.0, 3.0), seeds=seeds, steps=5)
    assert len(whole.points) > 6 and len(start.points) == 6 and not start.reached
    np.testing.assert_array_equal(start.points, whole.points[:6])
    np.testing.assert_array_equal(start.values, whole.values[:6])


@pytest.mark.parametrize(
    "kwargs, culprit",
    [
        (dict(speed=np.full((5, 5), np.nan)), "speed"),
        (dict(speed=-np.ones((5, 5))), "speed"),
        (dict(speed=np.full((5, 5), np.inf)), "speed"),
        (dict(initial=np.full((5, 5), -np.inf)), "initial"),
        (dict(speed=np.ones(5)), "speed"),
        (dict(initial=np.full((5, 4), 0.0)), "initial"),
        (dict(initial=np.full((5, 5), np.nan)), "initial"),
        (dict(spacing=-1.0), "spacing"),
        (dict(order=3), "order"),
        (dict(ceiling=np.zeros((2, 2))), "ceiling"),
    ],
)
def test_travel_time_rejects_bad_input(kwargs, culprit):
    args = dict(speed=np.ones((5, 5)), spacing=1.0, initial=np.where(np.eye(5) > 0, 0.0, np.inf))
    args.update(kwargs)
    with pytest.raises(InputError, match=culprit):
        travel_time(**args)


def test_bilinear_reads_the_finite_corners_only():
    a = np.array([[1.0, 3.0], [np.inf, 5.0]])
    assert bilinear(a, 0.0, 1.0) == 3.0  # a node reads its own value
    # At the cell's centre the three finite corners weigh a quarter each, renormalised to a third.
    assert bilinear(a, 0.5, 0.5) == pytest.approx(3.0)
    assert bilinear(a, 0.25, 0.0) == 1.0  # the infinite corner drops out of this edge
    assert bilinear(a, 1.0, 0.0) == np.inf  # on the infinite node, nothing finite has weight
    assert bilinear(np.full((2, 2), np.inf), 0.5, 0.5) == np.inf
    plane = np.add.outer(2.0 * np.arange(4.0), 3.0 * np.arange(5.0))
    assert bilinear(plane, 2.25, 3.5) == pytest.approx(2.0 * 2.25 + 3.0 * 3.5)
    assert bilinear(plane, 9.0, -1.0) == pytest.approx(bilinear(plane, 3.0, 0.0))  # clamped into the grid


def test_descend_steps_look_ahead_from_the_nearest_reached_node():
    g = square(41)
    v = np.ones(g.shape)
    src = (8.0, 8.0)
    phi = travel_time(v, g.spacing, point_source(g, src, v))
    path = descend_steps(g, phi, np.array([2.0, 2.0]), 4)
    assert len(path) == 5
    np.testing.assert_array_equal(path[0], (2.0, 2.0))
    assert np.all(np.diff(np.hypot(*(path - src).T)) < 0)  # every step closer to the source
    hidden = phi.copy()
    hidden[g.nearest_index((2.0, 2.0))] = np.inf  # the start's own node is not reached
    path = descend_steps(g, hidden, np.array([2.0, 2.0]), 4)
    assert math.dist(path[0], (2.0, 2.0)) == pytest.approx(g.spacing[0])  # starts on a reached neighbour
    assert descend_steps(g, np.full(g.shape, np.inf), np.array([2.0, 2.0]), 4) is None


def test_point_source_and_descend_reject_bad_points():
    g = square(11)
    v = np.ones(g.shape)
    with pytest.raises(InputError, match="outside the grid"):
        point_source(g, (11.0, 3.0), v)
    with pytest.raises(InputError, match="no passable grid node"):
        point_source(g, (5.0, 5.0), np.zeros(g.shape))
    phi = np.full(g.shape, np.inf)
    with pytest.raises(InputError, match="not on a finite value"):
        descend(g, phi, (5.0, 5.0))
    with pytest.raises(InputError, match="capture radius"):
        time_to_capture(phi, 1.0, -1.0)
