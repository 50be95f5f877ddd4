"""Safe-reachable-area pursuit on a grid (thesis 5.2.2, 5.3.2) against geometry worked out by hand:
Voronoi cells and Lemma 3 in the square, Apollonius disks for a faster pursuer, corners of the triangle."""

import math

import numpy as np
import pytest
from shapely.geometry import LineString, Polygon, box

from bearcat.maps import load_map, rasterize
from bearcat.solvers.errors import InputError
from bearcat.solvers.pursuit.fmm import (
    FarthestPointEvader,
    FmmAreaPursuit,
    GeodesicPursuit,
    TravelTimes,
    safe_set,
)

H = 0.1


@pytest.fixture(scope="module")
def domains():
    """The three thesis domains at 0.1 m (101 x 101 nodes), with their rasters."""
    out = {}
    for name in ("square-10", "triangle-10", "maze-10"):
        raster = rasterize(load_map(name), H)
        out[name] = (TravelTimes(raster.grid, raster.speed), raster)
    return out


def angle_deg(a, b) -> float:
    c = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def half_plane(e, p):
    """The points closer to ``e`` than to ``p``, as a large polygon."""
    e, p = np.asarray(e, float), np.asarray(p, float)
    n = (p - e) / np.linalg.norm(p - e)
    m, t = (p + e) / 2, np.array([-n[1], n[0]])
    return Polygon([m + 50 * t, m + 50 * t - 50 * n, m - 50 * t - 50 * n, m - 50 * t])


def voronoi_cell(e, pursuers, margin=0.0):
    cell = box(-margin, -margin, 10 + margin, 10 + margin)
    for p in pursuers:
        cell = cell.intersection(half_plane(e, p))
    return cell


def bisector_distance(mesh, e, p):
    """Signed distance of every node from the bisector of ``e`` and ``p`` (negative on e's side)."""
    e, p = np.asarray(e, float), np.asarray(p, float)
    n = (p - e) / np.linalg.norm(p - e)
    m = (p + e) / 2
    return (mesh[0] - m[0]) * n[0] + (mesh[1] - m[1]) * n[1]


def lemma3(e, p):
    """dA/dx_p of thesis Lemma 3 for one pursuer in the square: -(L/2) eta_h + D_v eta_v."""
    e, p = np.asarray(e, float), np.asarray(p, float)
    xi = e - p
    eta_h = xi / np.linalg.norm(xi)
    eta_v = np.array([-eta_h[1], eta_h[0]])
    m = (p + e) / 2
    line = box(0, 0, 10, 10).intersection(LineString([m - 50 * eta_v, m + 50 * eta_v]))
    s = (np.array(line.coords) - m) @ eta_v  # the ends of the line of control B along eta_v
    s_lo, s_hi = s.min(), s.max()
    big_l, small_l = s_hi - s_lo, -s_lo  # l: the part of B opposite to eta_v
    d_h = -big_l / 2
    d_v = (small_l**2 - (big_l - small_l) ** 2) / (2 * np.linalg.norm(xi))
    return d_h * eta_h + d_v * eta_v


def exact_area_gradient(e, pursuers, k, eps=1e-5):
    """Central differences of the exact Voronoi cell's area (shapely)."""
    g = np.zeros(2)
    for axis in range(2):
        q1, q2 = np.array(pursuers, float), np.array(pursuers, float)
        q1[k, axis] += eps
        q2[k, axis] -= eps
        g[axis] = (voronoi_cell(e, q1).area - voronoi_cell(e, q2).area) / (2 * eps)
    return g


SQUARE_CASES = [
    ((5.0, 5.0), [(2.0, 3.0)]),
    ((6.3, 4.1), [(2.2, 7.5), (8.1, 8.3)]),
    ((3.3, 6.1), [(4.2, 3.5), (6.5, 7.2), (1.1, 1.2)]),
    ((7.7, 2.2), [(1.3, 1.9), (5.0, 8.8), (9.2, 6.1)]),
    ((2.0, 2.0), [(8.0, 8.0)]),
]


# --------------------------------------------------------------------------- the safe set


@pytest.mark.parametrize("e, pursuers", SQUARE_CASES)
def test_equal_speeds_point_capture_gives_the_voronoi_cell(domains, e, pursuers):
    travel_times, raster = domains["square-10"]
    s = safe_set(travel_times, e, pursuers, capture_radius=0.0)
    # Each node stands for its h x h cell, so the node count measures the
    # cell within the square grown by half a spacing.
    exact = voronoi_cell(e, pursuers, margin=H / 2).area
    assert s.area == pytest.approx(exact, rel=0.02)
    mesh = raster.grid.mesh()
    dist = np.array([bisector_distance(mesh, e, p) for p in pursuers])
    inside = (dist < 0).all(axis=0)
    band = (np.abs(dist) <= 2 * H).any(axis=0)
    assert (inside & ~band).any()
    np.testing.assert_array_equal(s.mask[~band], inside[~band])
    # The set is bounded by the pursuer whose time to capture is least there.
    ties = [bisector_distance(mesh, p, q) for i, p in enumerate(pursuers) for q in pursuers[i + 1 :]]
    outside = ~s.mask & ~band & ~(np.abs(ties) <= 2 * H).any(axis=0)
    nearest = np.argmin([np.hypot(mesh[0] - p[0], mesh[1] - p[1]) for p in pursuers], axis=0)
    np.testing.assert_array_equal(s.owner[outside], nearest[outside])


def test_faster_pursuer_leaves_the_apollonius_disk(domains):
    travel_times, raster = domains["square-10"]
    e, p, k = np.array([4.1, 6.2]), np.array([6.3, 4.9]), 0.5  # evader at half the pursuer's speed
    s = safe_set(travel_times, e, [p], pursuer_speeds=2.0, capture_radius=0.0)
    centre = (e - k * k * p) / (1 - k * k)
    radius = k * np.linalg.norm(e - p) / (1 - k * k)
    r = np.hypot(raster.grid.mesh()[0] - centre[0], raster.grid.mesh()[1] - centre[1])
    band = np.abs(r - radius) <= 2 * H
    np.testing.assert_array_equal(s.mask[~band], (r < radius)[~band])


def test_safe_set_grows_as_a_slower_pursuer_approaches(domains):
    """Thesis Fig. 5.4: a pursuer at half the evader's speed, d away, is first
    on the Apollonius disk of radius 2d/3 around it, which shrinks as it
    closes in, so S_e gets larger; a faster pursuer's approach shrinks S_e."""
    travel_times, raster = domains["square-10"]
    e, u = np.array([2.0, 2.0]), np.array([0.8, 0.6])
    gaps = [4.0, 3.0, 2.0, 1.2]
    slow = [safe_set(travel_times, e, [e + d * u], pursuer_speeds=0.5, capture_radius=0) for d in gaps]
    fast = [safe_set(travel_times, e, [e + d * u], pursuer_speeds=1.5).area for d in gaps]
    assert np.all(np.diff([s.area for s in slow]) > 0), [s.area for s in slow]
    assert np.all(np.diff(fast) < 0), fast
    x, y = raster.grid.mesh()
    for d, s in zip(gaps, slow):
        centre = e + 4 * d / 3 * u
        r = np.hypot(x - centre[0], y - centre[1])
        assert not (s.mask & (r < 2 * d / 3 - 2 * H)).any()  # nothing of the pursuer's disk


def test_only_the_ratio_of_speeds_shapes_the_set(domains):
    """Doubling every speed halves every time and leaves S_e alone."""
    travel_times, _ = domains["triangle-10"]
    e, ps = (5.0, 8.5), [(2.0, 2.0), (8.0, 1.0)]
    slow = safe_set(travel_times, e, ps, evader_speed=1.0, pursuer_speeds=(0.5, 0.75))
    fast = safe_set(travel_times, e, ps, evader_speed=2.0, pursuer_speeds=(1.0, 1.5))
    np.testing.assert_array_equal(slow.mask, fast.mask)
    np.testing.assert_allclose(fast.evader_time[fast.mask], slow.evader_time[slow.mask] / 2, rtol=1e-12)
    np.testing.assert_allclose(fast.pursuer_times, slow.pursuer_times / 2, rtol=1e-12)
    assert slow.mask.any() and not slow.mask.all()


def test_evader_within_capture_radius_has_no_safe_set(domains):
    travel_times, _ = domains["square-10"]
    s = safe_set(travel_times, (5.0, 5.0), [(5.3, 5.2)], capture_radius=0.5)
    assert not s.mask.any() and s.area == 0.0


def test_cached_fronts_give_the_same_sets_as_fresh_travel_times(domains):
    """TravelTimes caches fronts by position at speed factor 1; every speed and
    radius must still give its own answer."""
    travel_times, raster = domains["triangle-10"]
    e, ps = (5.0, 8.5), [(2.0, 2.0), (8.0, 1.0)]
    for speeds, radius in ((1.0, 0.5), ((1.5, 0.8), 0.5), (1.0, 0.0), ((1.5, 0.8), 0.3)):
        cached = safe_set(travel_times, e, ps, pursuer_speeds=speeds, capture_radius=radius)
        fresh = safe_set(TravelTimes(raster.grid, raster.speed), e, ps, pursuer_speeds=speeds, capture_radius=radius)
        np.testing.assert_array_equal(cached.mask, fresh.mask)
        np.testing.assert_array_equal(cached.pursuer_times, fresh.pursuer_times)
    assert travel_times.travel_time((2.0, 2.0)) is travel_times.travel_time((2.0, 2.0))


def test_strategies_sharing_travel_times_share_fronts_and_the_safe_set(domains):
    """The evader and the pursuers asking about one state build its safe set
    once; a front and its time to capture are built once per position."""
    travel_times, _ = domains["square-10"]
    e, ps = (5.0, 5.0), [(1.0, 1.5), (8.5, 2.0)]
    FarthestPointEvader(travel_times).heading(e, ps)
    shared = safe_set(travel_times, e, ps)
    assert FmmAreaPursuit(travel_times).area_gradient(e, ps).safe is shared
    front = travel_times.front(np.array(ps[0]))
    assert travel_times.front(np.array(ps[0])) is front
    assert front.capture_time(0.5) is travel_times.capture_time(ps[0], 0.5)
    np.testing.assert_array_equal(front.capture_time(0.0), front.times)  # capture on contact
    assert front.source_speed == 1.0


def test_bad_inputs_name_the_culprit(domains):
    travel_times, _ = domains["triangle-10"]
    with pytest.raises(InputError, match="pursuer 2"):
        safe_set(travel_times, (1.0, 1.0), [(9.0, 9.0), (5.0, 5.0)])  # inside the triangle
    with pytest.raises(InputError, match="evader"):
        safe_set(travel_times, (11.0, 1.0), [(9.0, 9.0)])
    with pytest.raises(InputError, match="2 pursuer speeds for 1"):
        safe_set(travel_times, (1.0, 1.0), [(9.0, 9.0)], pursuer_speeds=(1.0, 2.0))
    with pytest.raises(InputError, match="gradient"):
        FmmAreaPursuit(travel_times, gradient="central")


# --------------------------------------------------------------------------- the area gradient


@pytest.mark.parametrize("e, pursuers", SQUARE_CASES)
def test_area_gradient_matches_lemma_3_in_the_square(domains, e, pursuers):
    travel_times, _ = domains["square-10"]
    boundary = FmmAreaPursuit(travel_times, capture_radius=0.0).area_gradient(e, pursuers)
    finite = FmmAreaPursuit(travel_times, capture_radius=0.0, gradient="finite").area_gradient(e, pursuers)
    for k in range(len(pursuers)):
        exact = exact_area_gradient(e, pursuers, k)
        if len(pursuers) == 1:
            np.testing.assert_allclose(lemma3(e, pursuers[0]), exact, rtol=1e-4, atol=1e-6)
        assert boundary.active[k] and finite.active[k]
        assert angle_deg(boundary.gradient[k], exact) < 5
        assert np.linalg.norm(boundary.gradient[k]) == pytest.approx(np.linalg.norm(exact), rel=0.1)
        assert angle_deg(finite.gradient[k], exact) < 10


def test_area_gradient_of_a_faster_pursuer_matches_the_apollonius_disk(domains):
    travel_times, _ = domains["square-10"]
    e, p, k = np.array([4.1, 6.2]), np.array([6.3, 4.9]), 0.5
    exact = -2 * math.pi * k * k * (e - p) / (1 - k * k) ** 2  # A = pi (k |e - p| / (1 - k^2))^2
    g = FmmAreaPursuit(travel_times, pursuer_speeds=2.0, capture_radius=0.0).area_gradient(e, [p]).gradient[0]
    assert angle_deg(g, exact) < 3
    assert np.linalg.norm(g) == pytest.approx(np.linalg.norm(exact), rel=0.05)


OPEN_CASES = [
    ("triangle-10", (7.3, 1.2), [(2.0, 8.0)]),  # it reaches the far side around the triangle
    ("triangle-10", (8.8, 2.4), [(3.9, 0.3), (0.3, 4.8)]),
    ("triangle-10", (2.0, 5.0), [(8.0, 5.5), (5.0, 1.0)]),
    ("triangle-10", (5.0, 8.5), [(4.5, 2.0)]),
    ("triangle-10", (8.5, 6.0), [(1.0, 2.0), (2.0, 9.0)]),
    ("square-10", (6.0, 3.0), [(2.0, 7.0), (8.5, 8.0)]),
]


def central_area_gradient(travel_times, e, pursuers, k, step=0.25):
    """Differences of the node count over +-2.5 spacings: too coarse to steer
    by, but smooth enough to check a direction against."""
    g = np.zeros(2)
    for axis in range(2):
        areas = []
        for sign in (1, -1):
            q = np.array(pursuers, float)
            q[k, axis] += sign * step
            areas.append(safe_set(travel_times, e, q).area)
        g[axis] = (areas[0] - areas[1]) / (2 * step)
    return g


@pytest.mark.parametrize("name, e, pursuers", OPEN_CASES)
def test_boundary_and_finite_gradients_agree_in_open_configurations(domains, name, e, pursuers):
    travel_times, _ = domains[name]
    boundary = FmmAreaPursuit(travel_times).area_gradient(e, pursuers)
    finite = FmmAreaPursuit(travel_times, gradient="finite").area_gradient(e, pursuers)
    np.testing.assert_array_equal(boundary.active, finite.active)
    assert boundary.active.all()
    for k in range(len(pursuers)):
        a, b = boundary.gradient[k], finite.gradient[k]
        assert a @ b / (np.linalg.norm(a) * np.linalg.norm(b)) > 0.9, (k, a, b)
        assert angle_deg(a, central_area_gradient(travel_times, e, pursuers, k)) < 5


@pytest.mark.parametrize(
    "e, pursuers",
    [
        ((7.5, 3.5), [(3.1, 6.7), (9.7, 5.5)]),
        ((6.5, 7.0), [(7.5, 4.8)]),
        ((1.0, 5.0), [(3.5, 3.2)]),
        ((5.0, 5.2), [(7.0, 5.0)]),
        ((8.0, 1.0), [(5.0, 2.0)]),
    ],
)
def test_boundary_gradient_in_the_maze_follows_the_area(domains, e, pursuers):
    """The capture disk reaches through the maze's half-metre walls, so parts
    of S_e end on a wall face where psi^c jumps: those stay put as a pursuer
    moves and must not count (there |grad f| from the geometry is meaningless)."""
    travel_times, _ = domains["maze-10"]
    ag = FmmAreaPursuit(travel_times).area_gradient(e, pursuers)
    for k in range(len(pursuers)):
        assert ag.active[k]
        assert angle_deg(ag.gradient[k], central_area_gradient(travel_times, e, pursuers, k, step=0.15)) < 8


def test_pursuer_without_an_active_boundary_has_no_gradient_and_pursues(domains):
    travel_times, _ = domains["square-10"]
    e, ps = (5.0, 5.0), [(3.0, 5.0), (1.0, 5.0)]  # the second hides behind the first
    ag = FmmAreaPursuit(travel_times).area_gradient(e, ps)
    assert ag.active.tolist() == [True, False]
    assert ag.boundary_length[1] == 0 and not ag.gradient[1].any()
    np.testing.assert_allclose(FmmAreaPursuit(travel_times).headings(e, ps)[1], [1.0, 0.0], atol=1e-9)


# --------------------------------------------------------------------------- headings


def assert_clear(raster, p, d):
    """A heading is a unit vector (or zero) whose next spacing, sampled every
    eighth, stays on free nodes, the agent's own node excepted."""
    n = np.linalg.norm(d)
    assert n == pytest.approx(1.0) or n == 0.0
    g = raster.grid
    own = g.nearest_index(p)
    for s in np.arange(1, 9) / 8 * H:
        q = p + s * d
        assert g.contains(q), (p, d)
        node = g.nearest_index(q)
        assert node == own or raster.free[node], (p, d, q)


def placements(raster, n, rng):
    """Random free points, half of them right against a wall or an obstacle."""
    free = raster.free
    wall = free & ~(
        np.pad(free, 1, constant_values=False)[:-2, 1:-1]
        & np.pad(free, 1, constant_values=False)[2:, 1:-1]
        & np.pad(free, 1, constant_values=False)[1:-1, :-2]
        & np.pad(free, 1, constant_values=False)[1:-1, 2:]
    )
    nodes = np.argwhere(wall if rng.random() < 0.5 else free)
    pts = raster.grid.lo + nodes[rng.choice(len(nodes), n, replace=False)] * H
    return np.clip(pts + rng.uniform(-0.03, 0.03, pts.shape), 0.0, 10.0)  # same nearest node


@pytest.mark.parametrize("name", ["triangle-10", "maze-10"])
def test_headings_never_point_into_obstacles(domains, name):
    travel_times, raster = domains[name]
    rng = np.random.default_rng(7)
    strategies = [
        FmmAreaPursuit(travel_times),
        FmmAreaPursuit(travel_times, gradient="finite"),
        GeodesicPursuit(travel_times),
    ]
    checked = 0
    for _trial in range(24):
        pts = placements(raster, 3, rng)
        if np.hypot(*(pts[1:] - pts[0]).T).min() <= 0.6:
            continue
        e, ps = pts[0], pts[1:]
        for strategy in strategies:
            for p, d in zip(ps, strategy.headings(e, ps)):
                assert_clear(raster, p, d)
                checked += 1
        assert_clear(raster, e, FarthestPointEvader(travel_times).heading(e, ps))
    assert checked > 30


def test_area_heading_into_an_obstacle_slides_along_it(domains):
    """At the triangle's lower left corner, with the evader below, -dA/dx_p
    points into the triangle; the heading turns along its face and still lowers the area."""
    travel_times, raster = domains["triangle-10"]
    e, p = (5.0, 1.0), np.array([3.0, 3.6])
    g = FmmAreaPursuit(travel_times).area_gradient(e, [p]).gradient[0]
    raw = -g / np.linalg.norm(g)
    with pytest.raises(AssertionError):
        assert_clear(raster, p, raw)
    d = FmmAreaPursuit(travel_times).headings(e, [p])[0]
    assert_clear(raster, p, d)
    assert 10 < angle_deg(d, raw) < 85


def test_geodesic_pursuit_goes_around_the_triangle(domains):
    travel_times, raster = domains["triangle-10"]
    e, p = np.array([5.0, 8.5]), np.array([4.5, 2.0])  # the straight line runs through the triangle
    corner = np.array([3.0, 3.5])
    d = GeodesicPursuit(travel_times).headings(e, [p])[0]
    assert angle_deg(d, corner - p) < 10
    length, path = 0.0, [p.copy()]
    step = 0.05
    while np.linalg.norm(p - e) > 0.5 and length < 20:
        p = p + step * GeodesicPursuit(travel_times).headings(e, [p])[0]
        length += step
        path.append(p.copy())
        assert raster.free[raster.grid.nearest_index(p)]
    geodesic = np.linalg.norm(corner - path[0]) + np.linalg.norm(e - corner)
    assert length <= 1.05 * geodesic
    assert min(q[0] for q in path) < 3.2  # by the left corner


# --------------------------------------------------------------------------- the evader


def test_farthest_point_evader_holds_its_target_then_retargets(domains):
    travel_times, _ = domains["square-10"]
    e, ps = np.array([6.0, 4.0]), np.array([[2.0, 2.0], [3.0, 8.0]])
    evader = FarthestPointEvader(travel_times)
    d = evader.heading(e, ps)
    s = safe_set(travel_times, e, ps)
    far = np.unravel_index(np.argmax(np.where(s.mask, s.evader_time, -np.inf)), s.mask.shape)
    np.testing.assert_allclose(evader.target, travel_times.grid.point(far))
    assert s.evader_time[far] == s.evader_time[s.mask].max()
    assert angle_deg(d, evader.target - e) < 3  # in the open the geodesic is the straight line
    first = evader.target.copy()

    # The pursuers close in; the target holds until the evader gets there.
    evader.heading(e + 0.3 * d, ps + 0.5)
    np.testing.assert_array_equal(evader.target, first)
    assert evader.retargets == 1

    near = first - 0.2 * (first - e) / np.linalg.norm(first - e)  # within r_c / 2 = 0.25
    evader.heading(near, ps)
    assert evader.retargets == 2
    s = safe_set(travel_times, near, ps)
    assert s.mask[travel_times.grid.nearest_index(evader.target)]
    assert np.linalg.norm(evader.target - first) > 2.0
    assert s.evader_time[travel_times.grid.nearest_index(evader.target)] == s.evader_time[s.mask].max()


def test_area_pursuit_captures_the_farthest_point_evader_sooner_than_pure_pursuit(domains):
    """Thesis 5.3.2, Fig. 5.7: two pursuers starting side by side spread out
    and herd the evader under the area strategy; under pure pursuit they
    chase it round the square together."""
    travel_times, _ = domains["square-10"]

    def play(strategy):
        evader = FarthestPointEvader(travel_times)
        e, ps = np.array([5.0, 5.0]), np.array([[1.0, 1.5], [1.5, 1.0]])
        dt = 0.1
        for step in range(400):
            de, dp = evader.heading(e, ps), strategy.headings(e, ps)
            e = np.clip(e + dt * de, 0, 10)
            ps = np.clip(ps + dt * dp, 0, 10)
            if np.hypot(*(ps - e).T).min() <= 0.5:
                return (step + 1) * dt
        return math.inf

    area, pure = play(FmmAreaPursuit(travel_times)), play(GeodesicPursuit(travel_times))
    assert area < 20 and area < 0.75 * pure
