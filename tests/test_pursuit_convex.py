"""Convex, equal-speed safe-reachable-area pursuit (thesis 5.2.1): the cell
against shapely's own construction, Lemma 3 and eq. 5.12 against finite
differences of the area, Lemma 5 (the area never grows, and stands still
only against gamma*), Lemma 4 (headings from the boundary point inwards),
the farthest-point evader of 5.3.2, and capture in closed loop (Theorem 8).

States are drawn by seeded generators in the thesis's 10 x 10 square and in
an irregular convex pentagon, with pursuers kept at least a capture radius
from the evader as the game guarantees until capture."""

import numpy as np
import pytest
import shapely
from shapely.geometry import LineString, Point, Polygon
from shapely.geometry.polygon import orient

from bearcat.solvers.errors import InputError
from bearcat.solvers.pursuit.convex import (
    ConvexAreaPursuit,
    ConvexFarthestPointEvader,
    StraightPursuit,
    area_minimising_headings,
    convex_area_gradient,
    evader_area_gradient,
    line_of_control,
    pure_pursuit_headings,
    voronoi_cell,
)

SQUARE = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
PENTAGON = np.array([[0.0, 0.0], [9.0, 1.0], [12.0, 6.0], [7.0, 11.0], [1.0, 8.0]])
DOMAINS = {"square": SQUARE, "pentagon": PENTAGON}
CAPTURE_RADIUS = 0.5  # thesis 5.3.1


def random_point(rng, domain):
    poly = Polygon(domain)
    lo, hi = domain.min(0), domain.max(0)
    while True:
        q = rng.uniform(lo, hi)
        if poly.contains(Point(q)):
            return q


def random_state(rng, domain, n, gap=CAPTURE_RADIUS):
    """An evader and ``n`` pursuers inside ``domain``, none within ``gap`` of the evader."""
    e = random_point(rng, domain)
    p = []
    while len(p) < n:
        q = random_point(rng, domain)
        if np.hypot(*(q - e)) > gap:
            p.append(q)
    return e, np.array(p).reshape(n, 2)


def area(vertices):
    x, y = np.asarray(vertices).T
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)) if len(x) else 0.0


def bisector_halfplane(e, q, reach=1e3):
    """{y : |y - e| <= |y - q|} as a (very large) shapely polygon."""
    n = (q - e) / np.hypot(*(q - e))
    t = np.array([-n[1], n[0]])
    m = 0.5 * (e + q)
    return Polygon([m + reach * t, m + reach * t - reach * n, m - reach * t - reach * n, m - reach * t])


def shapely_cell(domain, e, pursuers):
    cell = Polygon(domain)
    for q in pursuers:
        cell = cell.intersection(bisector_halfplane(e, q))
    return orient(cell, 1.0)


def shapely_line_of_control(cell, e, q):
    """Length of the cell's boundary that lies on the bisector of e and q."""
    n = (q - e) / np.hypot(*(q - e))
    t = np.array([-n[1], n[0]])
    m = 0.5 * (e + q)
    line = LineString([m - 1e3 * t, m + 1e3 * t]).buffer(1e-9, cap_style="flat")
    return cell.boundary.intersection(line).length


def rotate_to_match(ours, theirs):
    """``ours`` rolled so that its first corner is the one nearest ``theirs[0]``."""
    k = int(np.argmin(np.hypot(*(ours - theirs[0]).T)))
    return np.roll(ours, -k, axis=0)


# --- the cell ---


@pytest.mark.parametrize("name", DOMAINS)
def test_cell_matches_shapely_halfplane_intersection(name):
    domain = DOMAINS[name]
    rng = np.random.default_rng(1)
    shadowed = 0
    for _ in range(150):
        e, p = random_state(rng, domain, int(rng.integers(1, 7)))
        ours = voronoi_cell(domain, e, p)
        theirs = shapely_cell(domain, e, p)
        ring = np.array(shapely.remove_repeated_points(theirs, 1e-10).simplify(0).exterior.coords)[:-1]
        assert area(ours) == pytest.approx(theirs.area, abs=1e-9)
        assert area(ours) > 0  # counter-clockwise
        assert len(ours) == len(ring)
        np.testing.assert_allclose(rotate_to_match(ours, ring), ring, atol=1e-9)
        g = convex_area_gradient(domain, e, p)
        assert g.area == pytest.approx(theirs.area, abs=1e-9)
        for i, q in enumerate(p):
            on_bisector = shapely_line_of_control(theirs, e, q)
            assert g.active[i] == (on_bisector > 1e-6), (e, p, i)
            assert g.line_length[i] == pytest.approx(on_bisector, abs=1e-6)
            ends = line_of_control(domain, e, p, i)
            assert len(ends) == (2 if g.active[i] else 0)
            if len(ends):  # a stretch of i's bisector, as long as shapely finds it
                assert np.hypot(*(ends[1] - ends[0])) == pytest.approx(on_bisector, abs=1e-6)
                np.testing.assert_allclose(np.hypot(*(ends - q).T), np.hypot(*(ends - e).T), atol=1e-9)
            if not g.active[i]:
                shadowed += 1
                assert np.all(g.gradient[i] == 0)
    assert shadowed > 50  # pursuers without a line of control were exercised


def test_pursuer_behind_another_has_no_line_of_control():
    g = convex_area_gradient(SQUARE, [2.0, 5.0], [[4.0, 5.0], [7.0, 5.0]])
    assert g.active.tolist() == [True, False]
    np.testing.assert_allclose(line_of_control(SQUARE, [2.0, 5.0], [[4.0, 5.0], [7.0, 5.0]], 0), [[3, 0], [3, 10]])
    assert line_of_control(SQUARE, [2.0, 5.0], [[4.0, 5.0], [7.0, 5.0]], 1).shape == (0, 2)
    assert g.area == pytest.approx(30.0)
    np.testing.assert_allclose(g.gradient[1], 0.0)
    np.testing.assert_allclose(g.line_length, [10.0, 0.0])


def test_pursuer_on_the_evader_leaves_no_cell():
    g = convex_area_gradient(SQUARE, [5.0, 5.0], [[5.0, 5.0], [1.0, 1.0]])
    assert g.area == 0.0 and len(g.vertices) == 0 and not g.active.any()
    np.testing.assert_array_equal(area_minimising_headings(SQUARE, [5.0, 5.0], [[5.0, 5.0]]), [[0.0, 0.0]])


def test_domain_may_be_a_closed_clockwise_ring():
    e, p = np.array([3.0, 4.0]), np.array([[7.0, 5.0], [6.0, 8.0]])
    ring = np.vstack([PENTAGON[::-1], PENTAGON[-1:]])
    np.testing.assert_allclose(
        area_minimising_headings(ring, e, p), area_minimising_headings(PENTAGON, e, p), atol=1e-12
    )
    assert area(voronoi_cell(ring, e, p)) > 0


@pytest.mark.parametrize(
    "domain, evader, pursuers, culprit",
    [
        ([[0, 0], [10, 0], [5, 1], [5, 10]], [1, 1], [[2, 2]], "not convex"),
        ([[0, 0], [1, 1], [2, 2]], [1, 1], [[2, 2]], "no area"),
        (SQUARE, [11.0, 5.0], [[2.0, 2.0]], "evader"),
        (SQUARE, [5.0, 5.0], [[2.0, 2.0], [2.0, -1.0]], "pursuer 1"),
        (SQUARE, [5.0, 5.0], np.zeros((0, 2)), "pursuers"),
    ],
)
def test_bad_input_is_refused_by_name(domain, evader, pursuers, culprit):
    with pytest.raises(InputError, match=culprit):
        area_minimising_headings(domain, evader, pursuers)


# --- Lemma 3 and eq. 5.12 ---


def central_difference(f, x, h=1e-6):
    grad = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        step = np.zeros_like(x)
        step[idx] = h
        grad[idx] = (f(x + step) - f(x - step)) / (2 * h)
    return grad


@pytest.mark.parametrize("name", DOMAINS)
def test_lemma3_gradient_matches_finite_differences(name):
    domain = DOMAINS[name]
    rng = np.random.default_rng(2)
    crosses = beyond = short_of = checked = 0
    for _ in range(200):
        e, p = random_state(rng, domain, int(rng.integers(1, 5)))
        g = convex_area_gradient(domain, e, p)
        # Skip the rare states where a corner of the cell changes within the
        # difference step: the area is only piecewise smooth there.
        probes = [convex_area_gradient(domain, e + s, p) for s in ([1e-6, 0], [-1e-6, 0], [0, 1e-6], [0, -1e-6])]
        if any(len(q.vertices) != len(g.vertices) or (q.active != g.active).any() for q in probes):
            continue
        checked += 1
        fd_p = central_difference(lambda x, e=e: area(voronoi_cell(domain, e, x)), p)
        np.testing.assert_allclose(g.gradient, fd_p, atol=1e-6)
        fd_e = central_difference(lambda x, p=p: area(voronoi_cell(domain, x, p)), e)
        np.testing.assert_allclose(evader_area_gradient(domain, e, p), fd_e, atol=1e-6)
        length, split = g.line_length[g.active], g.line_split[g.active]  # the thesis's L and l
        crosses += int(np.sum((split >= 0) & (split <= length)))  # first case of Lemma 3
        beyond += int(np.sum(split > length))  # second case, B_i on the -eta_v side (Fig. 5.2c)
        short_of += int(np.sum(split < 0))  # second case, B_i on the +eta_v side
    assert checked > 150
    assert crosses > 50 and beyond > 10 and short_of > 10


def test_lemma3_for_one_pursuer_across_the_square():
    """Fig. 5.1a in the middle of the square: B is the whole vertical chord,
    cut in half by xi, so D_h A = -L/2 = -5 and D_v A = 0."""
    g = convex_area_gradient(SQUARE, [4.0, 5.0], [[6.0, 5.0]])
    assert g.area == pytest.approx(50.0)
    assert g.line_length[0] == pytest.approx(10.0) and g.line_split[0] == pytest.approx(5.0)
    np.testing.assert_allclose(g.gradient[0], [5.0, 0.0])  # eta_h points -x: moving toward the evader costs 5
    np.testing.assert_allclose(g.evader_gradient, [5.0, 0.0])  # the evader stepping away pushes B with it
    np.testing.assert_allclose(area_minimising_headings(SQUARE, [4.0, 5.0], [[6.0, 5.0]]), [[-1.0, 0.0]])


# --- Lemma 5: dA/dt <= 0 ---


def gamma_star(e, q, length, split):
    """Eq. 5.14 built from the thesis's alpha_h, alpha_v and local frame (L = length, l = split)."""
    xi = e - q
    eta_h = xi / np.hypot(*xi)
    eta_v = np.array([-eta_h[1], eta_h[0]])
    alpha_h = -length / 2
    alpha_v = (split**2 - (length - split) ** 2) / (2 * np.hypot(*xi))
    return (alpha_h * eta_h - alpha_v * eta_v) / np.hypot(alpha_h, alpha_v)


def evader_inputs(rng, count):
    """Admissible evader velocities: on the unit circle and inside the disk."""
    angles = rng.uniform(0, 2 * np.pi, count)
    radii = np.where(np.arange(count) % 2 == 0, 1.0, np.sqrt(rng.uniform(0, 1, count)))
    return np.column_stack([np.cos(angles), np.sin(angles)]) * radii[:, None]


@pytest.mark.parametrize("name", DOMAINS)
def test_lemma5_one_pursuer_area_never_grows_and_stalls_only_at_gamma_star(name):
    domain = DOMAINS[name]
    rng = np.random.default_rng(3)
    for _ in range(100):
        e, p = random_state(rng, domain, 1)
        g = convex_area_gradient(domain, e, p)
        u = area_minimising_headings(domain, e, p)
        best = gamma_star(e, p[0], g.line_length[0], g.line_split[0])
        np.testing.assert_allclose(g.evader_gradient / np.hypot(*g.evader_gradient), best, atol=1e-12)
        size = np.hypot(*g.gradient[0])
        assert abs(np.sum(g.gradient * u) + g.evader_gradient @ best) < 1e-12 * size
        for d in evader_inputs(rng, 40):
            rate = np.sum(g.gradient * u) + g.evader_gradient @ d
            # Strictly below zero by at least |grad| |d - gamma*|^2 / 2.
            assert rate <= -0.5 * size * np.sum((d - best) ** 2) + 1e-12 * size
        # The rate is the true one: the area along the joint motion.
        d = evader_inputs(rng, 1)[0]
        tau = 1e-6
        moved = [area(voronoi_cell(domain, e + s * tau * d, p + s * tau * u)) for s in (1, -1)]
        rate = np.sum(g.gradient * u) + g.evader_gradient @ d
        assert (moved[0] - moved[1]) / (2 * tau) == pytest.approx(rate, abs=1e-5)


@pytest.mark.parametrize("name", DOMAINS)
def test_lemma5_several_pursuers_area_never_grows(name):
    domain = DOMAINS[name]
    rng = np.random.default_rng(4)
    for _ in range(100):
        e, p = random_state(rng, domain, int(rng.integers(2, 5)))
        g = convex_area_gradient(domain, e, p)
        u = area_minimising_headings(domain, e, p)
        d = evader_inputs(rng, 40)
        rates = np.sum(g.gradient * u) + d @ g.evader_gradient
        assert rates.max() <= 1e-12 * np.abs(g.gradient).sum()
        tau = 1e-6
        moved = [area(voronoi_cell(domain, e + s * tau * d[0], p + s * tau * u)) for s in (1, -1)]
        assert (moved[0] - moved[1]) / (2 * tau) == pytest.approx(rates[0], abs=1e-5)


# --- Lemma 4 and the headings ---


def boundary_point(rng, domain):
    """A point on a random edge (a corner one time in five) and the outward normals there."""
    m = len(domain)
    k = int(rng.integers(m))
    a, b = domain[k], domain[(k + 1) % m]
    normal = lambda a, b: np.array([b[1] - a[1], a[0] - b[0]]) / np.hypot(*(b - a))  # noqa: E731
    if rng.uniform() < 0.2:
        return b.copy(), [normal(a, b), normal(b, domain[(k + 2) % m])]
    return a + rng.uniform(0.02, 0.98) * (b - a), [normal(a, b)]


@pytest.mark.parametrize("name", DOMAINS)
def test_lemma4_headings_from_the_boundary_point_into_the_domain(name):
    domain = DOMAINS[name]
    rng = np.random.default_rng(5)
    seen = 0
    for _ in range(300):
        e, others = random_state(rng, domain, int(rng.integers(0, 3)))
        q, normals = boundary_point(rng, domain)
        if np.hypot(*(q - e)) <= CAPTURE_RADIUS:
            continue
        p = np.vstack([q[None], others])
        g = convex_area_gradient(domain, e, p)
        if not g.active[0]:
            continue
        seen += 1
        h = area_minimising_headings(domain, e, p)[0]
        for n in normals:
            assert h @ n <= 1e-12
    assert seen > 150


@pytest.mark.parametrize("name", DOMAINS)
def test_headings_are_unit_and_aim_at_the_middle_of_the_line_of_control(name):
    """-dA/dx_p^i is parallel to (midpoint of B_i) - x_p^i: Lemma 3 read
    as a boundary integral. Pursuers without B_i run straight at the evader."""
    domain = DOMAINS[name]
    rng = np.random.default_rng(6)
    strategy = ConvexAreaPursuit(domain)
    for _ in range(100):
        e, p = random_state(rng, domain, int(rng.integers(1, 6)))
        h = strategy.headings(e, p)
        np.testing.assert_allclose(np.hypot(*h.T), 1.0)
        cell = shapely_cell(domain, e, p)
        g = convex_area_gradient(domain, e, p)
        straight = pure_pursuit_headings(e, p)
        for i, q in enumerate(p):
            if g.active[i]:
                n = (q - e) / np.hypot(*(q - e))
                m = 0.5 * (e + q)
                t = np.array([-n[1], n[0]])
                line = LineString([m - 1e3 * t, m + 1e3 * t]).buffer(1e-9, cap_style="flat")
                on_b = np.array(cell.boundary.intersection(line).centroid.coords[0])
                aim = (on_b - q) / np.hypot(*(on_b - q))
                np.testing.assert_allclose(h[i], aim, atol=1e-6)
            else:
                np.testing.assert_allclose(h[i], straight[i])
    np.testing.assert_allclose(StraightPursuit().headings([0.0, 0.0], [[3.0, 4.0]]), [[-0.6, -0.8]])


# --- the farthest-point evader of 5.3.2 ---


def farthest_corner(domain, e, p):
    corners = np.array(shapely_cell(domain, e, p).exterior.coords)[:-1]
    return corners[np.argmax(np.hypot(*(corners - e).T))]


def test_farthest_point_evader_keeps_its_target_until_within_half_the_capture_radius():
    rng = np.random.default_rng(7)
    for _ in range(20):
        e, p = random_state(rng, SQUARE, 2, gap=2.0)
        evader = ConvexFarthestPointEvader(SQUARE, CAPTURE_RADIUS)
        first = farthest_corner(SQUARE, e, p)
        h = evader.heading(e, p)
        np.testing.assert_allclose(evader.target, first, atol=1e-9)
        np.testing.assert_allclose(h, (first - e) / np.hypot(*(first - e)), atol=1e-12)
        first = evader.target.copy()
        # Walk to it at 0.05 a step while the pursuers drift: the target
        # holds until the evader is within r_c / 2 of it, then moves on.
        drift = rng.normal(size=p.shape) * 0.02
        while np.hypot(*(first - e)) > CAPTURE_RADIUS / 2:
            evader.heading(e, p)
            np.testing.assert_array_equal(evader.target, first)
            e = e + 0.05 * (first - e) / np.hypot(*(first - e))
            p = np.clip(p + drift, 0, 10)
        h = evader.heading(e, p)
        np.testing.assert_allclose(evader.target, farthest_corner(SQUARE, e, p), atol=1e-9)
        assert np.hypot(*(evader.target - e)) > CAPTURE_RADIUS / 2
        np.testing.assert_allclose(np.hypot(*h), 1.0)


def test_farthest_point_evader_stands_still_with_nowhere_to_go():
    evader = ConvexFarthestPointEvader(SQUARE, CAPTURE_RADIUS)
    np.testing.assert_array_equal(evader.heading([5.0, 5.0], [[5.0, 5.0]]), [0.0, 0.0])
    assert evader.target is None


# --- closed loop (Theorem 8, thesis 5.3.1 settings) ---


def chase(strategy, domain, e, p, dt=0.01, max_time=60.0):
    """Capture time of ``strategy`` against the farthest-point evader, or
    None; and the largest one-step growth of the area seen."""
    evader = ConvexFarthestPointEvader(domain, CAPTURE_RADIUS)
    e, p = e.copy(), p.copy()
    growth, last = 0.0, area(voronoi_cell(domain, e, p))
    for step in range(int(max_time / dt)):
        e_next = e + dt * evader.heading(e, p)
        p = p + dt * strategy.headings(e, p)
        e = e_next
        if np.hypot(*(p - e).T).min() <= CAPTURE_RADIUS:
            return (step + 1) * dt, growth
        now = area(voronoi_cell(domain, e, p))
        growth, last = max(growth, now - last), now
    return None, growth


def test_area_pursuit_captures_the_farthest_point_evader():
    rng = np.random.default_rng(8)
    area_pursuit = ConvexAreaPursuit(SQUARE)
    for n in (1, 2, 3):
        for _ in range(2):
            e, p = random_state(rng, SQUARE, n, gap=3.0)
            dt = 0.02
            time, growth = chase(area_pursuit, SQUARE, e, p, dt=dt)
            assert time is not None, (n, e, p)
            # Lemma 5 in discrete time: the area grows by O(dt^2) a step at most.
            assert growth <= 10 * dt**2
