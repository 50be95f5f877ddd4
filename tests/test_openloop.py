"""The open-loop reach-avoid game (thesis 4.1-4.2) against geometry we can work out by hand."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from bearcat.solvers.errors import InputError
from bearcat.solvers.grid import Grid
from bearcat.solvers.marching import fmm
from bearcat.solvers.marching.openloop import Defender, solve_openloop


def open_square(side=40.0, h=0.25):
    g = Grid.covering((0.0, 0.0), (side, side), h)
    return g, np.ones(g.shape), g.mesh()


def disk(mesh, centre, radius):
    x, y = mesh
    return np.hypot(x - centre[0], y - centre[1]) <= radius


def corner_values(field, grid, points):
    """Bilinear weights and values at the corners of each point's cell."""
    f = grid.fractional_index(points)
    i = np.clip(np.floor(f).astype(int), 0, np.asarray(grid.shape) - 2)
    t = f - i
    out = []
    for a in (0, 1):
        for b in (0, 1):
            w = (t[:, 0] if a else 1 - t[:, 0]) * (t[:, 1] if b else 1 - t[:, 1])
            out.append((w, field[i[:, 0] + a, i[:, 1] + b]))
    return out


def interpolate_where(field, grid, points, use):
    """Bilinear interpolation of ``field`` over the corners where ``use`` holds."""
    num = den = 0
    for (w, c), (_, ok) in zip(corner_values(field, grid, points), corner_values(use, grid, points)):
        use_it = ok & (w > 0)
        num = num + np.where(use_it, w * np.where(use_it, c, 0.0), 0.0)
        den = den + np.where(use_it, w, 0.0)
    return num / den


def assert_path_is_safe_and_consistent(sol, attacker, targets, speeds, walk_tolerance=0.04):
    g, path = sol.grid, sol.path
    assert sol.reached and path is not None
    np.testing.assert_array_equal(path.points[0], attacker)
    assert path.times[0] == 0.0
    assert np.all(np.diff(path.times) > 0)
    assert path.times[-1] == pytest.approx(sol.value)
    goal_idx = g.nearest_index(path.points[-1])
    assert targets[-1][goal_idx]
    assert path.stage_starts[0] == 0 and list(path.stage_starts) == sorted(path.stage_starts)
    h = max(g.spacing)
    for k, start in enumerate(path.stage_starts[1:], start=1):
        # A stage begins on the previous target, within half a cell.
        near = np.rint(g.fractional_index(path.points[start])).astype(int)
        assert targets[k - 1][tuple(near)]
    bounds = list(path.stage_starts) + [len(path.points)]
    for k, stage in enumerate(sol.stages):
        seg = path.points[bounds[k] : bounds[k + 1]]
        times = path.times[bounds[k] : bounds[k + 1]]
        # Safe: arrival before capture at every vertex, with psi^c read like phi.
        psi_c = interpolate_where(sol.capture_time, g, seg, stage.safe)
        assert np.all(times < psi_c)
        # And against plain bilinear psi^c, up to a cell of defender travel.
        psi_bilinear = interpolate_where(sol.capture_time, g, seg, np.ones(g.shape, bool))
        assert np.all(times < psi_bilinear + h)
        # Never on an impassable node.
        idx = np.rint(g.fractional_index(seg)).astype(int)
        assert np.all(speeds[k][idx[:, 0], idx[:, 1]] > 0)
    # The value is the time to walk the path at the local top speed.
    walked = 0.0
    for k in range(len(sol.stages)):
        seg = path.points[bounds[k] : bounds[k + 1] + 1]
        mid = (seg[1:] + seg[:-1]) / 2
        v = interpolate_where(speeds[k], g, mid, speeds[k] > 0)
        walked += np.sum(np.hypot(*np.diff(seg, axis=0).T) / v)
    if walk_tolerance is not None:
        assert walked == pytest.approx(sol.value, rel=walk_tolerance)


def test_equal_speeds_with_capture_radius_is_the_hyperbola_region():
    g, v, mesh = open_square()
    x, y = mesh
    xa, xd, r = (12.0, 17.0), (26.0, 22.0), 2.0
    sol = solve_openloop(g, xa, [v], [disk(mesh, (3, 35), 1.5)], [Defender(xd, v, r)])
    margin = np.hypot(x - xd[0], y - xd[1]) - r - np.hypot(x - xa[0], y - xa[1])
    clear = np.abs(margin) > 2 * g.spacing[0]
    safe = sol.stages[0].safe
    np.testing.assert_array_equal(safe[clear], (margin > 0)[clear])
    assert sol.stages[0].safe_area == pytest.approx(safe.sum() * g.cell_area)


def test_twice_as_fast_attacker_avoids_the_apollonius_disk_but_not_only_it():
    """Fig. 4.1: S lies outside the disk where the defender arrives first, yet
    S is not that disk's complement: behind the defender it is not reachable."""
    g, v, mesh = open_square(side=60.0, h=0.5)
    x, y = mesh
    xa, xd = (10.0, 30.0), (25.0, 30.0)
    sol = solve_openloop(g, xa, [2 * v], [disk(mesh, (5, 55), 2)], [Defender(xd, v)])
    safe = sol.stages[0].safe
    apollonius = np.hypot(x - xa[0], y - xa[1]) / 2 - np.hypot(x - xd[0], y - xd[1])
    assert not np.any(safe & (apollonius > g.spacing[0]))
    assert safe[disk(mesh, (3, 30), 5) | disk(mesh, (10, 55), 3)].all()
    # Just behind the disk (it spans x in [20, 40] on the axis), outside it by
    # a margin, is reached only by going around: too late.
    behind = (x > 40.5) & (x < 43) & (np.abs(y - 30) < 1) & (apollonius < -0.5)
    assert behind.any() and not safe[behind].any()
    # Far behind, going around the disk is fast enough.
    assert safe[g.nearest_index((58.0, 30.0))]


def test_many_defenders_combine_as_the_minimum_capture_time():
    g, v, mesh = open_square()
    xa, target = (12.0, 17.0), disk(mesh, (3, 35), 1.5)
    defenders = [
        Defender((30.0, 20.0), v, 1.5),
        Defender((20.0, 35.0), 1.2 * v, 0.5),
        Defender((15.0, 5.0), 0.8 * v, 2.0),
    ]
    together = solve_openloop(g, xa, [v], [target], defenders)
    alone = [solve_openloop(g, xa, [v], [target], [d]) for d in defenders]
    np.testing.assert_array_equal(together.capture_time, np.minimum.reduce([s.capture_time for s in alone]))
    # Each single-defender set is convex and star-shaped from the attacker
    # here, so straight paths stay in every one and S is their intersection.
    np.testing.assert_array_equal(together.stages[0].safe, np.logical_and.reduce([s.stages[0].safe for s in alone]))


def test_many_defenders_can_block_what_each_alone_leaves_open():
    """Two corridors around a block, one defender at each: either alone leaves
    the other way open, together they close both. S is then smaller than the
    intersection of the single-defender sets."""
    g = Grid.covering((0.0, 0.0), (40.0, 20.0), 0.5)
    x, y = g.mesh()
    v = np.ones(g.shape)
    v[(x >= 5) & (x <= 35) & (y >= 5) & (y <= 15)] = 0
    target = disk((x, y), (20, 18), 1.0)
    left, right = Defender((2.0, 10.0), v, 1.0), Defender((38.0, 10.0), v, 1.0)
    sols = [solve_openloop(g, (20.0, 2.0), [4 * v], [target], d) for d in ([left], [right], [left, right])]
    assert sols[0].reached and sols[1].reached
    assert not sols[2].reached and sols[2].blocked_stage == 0 and sols[2].path is None
    inside = g.nearest_index((20.0, 18.0))
    assert sols[0].stages[0].safe[inside] and sols[1].stages[0].safe[inside]
    assert not sols[2].stages[0].safe[inside]
    both = sols[2].stages[0].safe
    assert not np.any(both & ~(sols[0].stages[0].safe & sols[1].stages[0].safe))


def test_two_stages_beat_concatenated_single_stages_fig_4_2():
    g, v, mesh = open_square()
    x, y = mesh
    bar = (np.abs(x - 20) <= 0.3) & (y >= 5) & (y <= 35)
    flag = disk(mesh, (35, 35), 2.0)
    xa = (5.0, 20.0)
    two = solve_openloop(g, xa, [v, v], [bar, flag], [])
    one = solve_openloop(g, xa, [v], [bar], [])
    z = one.stages[0].goal
    then = fmm.travel_time(v, g.spacing, fmm.point_source(g, z, v))
    concatenated = one.stages[0].value + then[flag].min()
    # Analytic: straight from the attacker to the flag crosses the bar.
    assert two.value == pytest.approx(math.hypot(30, 15) - 2, rel=0.02)
    assert concatenated == pytest.approx(15 + math.hypot(15, 15) - 2, rel=0.02)
    assert two.value < concatenated - 2.0
    assert two.stages[0].value == pytest.approx(one.stages[0].value)
    assert_path_is_safe_and_consistent(two, xa, [bar, flag], [v, v])
    # The two-stage path crosses the bar near y = 27.5, not at the nearest point.
    junction = two.path.points[two.path.stage_starts[1]]
    assert junction[1] == pytest.approx(27.5, abs=1.0)


def test_two_stages_with_defenders_never_worse_than_concatenation():
    """Concatenation: the best stage-1 goal, then stage 2 from there starting at
    the stage-1 time against the same (still moving) defenders."""
    g, v, mesh = open_square()
    bar = (np.abs(mesh[0] - 20) <= 0.3) & (mesh[1] >= 5) & (mesh[1] <= 35)
    flag = disk(mesh, (35, 35), 2.0)
    xa = (5.0, 20.0)
    defenders = [Defender((30.0, 10.0), 0.5 * v, 1.0), Defender((12.0, 36.0), 0.4 * v, 1.0)]
    two = solve_openloop(g, xa, [v, 0.8 * v], [bar, flag], defenders)
    one = solve_openloop(g, xa, [v], [bar], defenders)
    z, t1 = one.stages[0].goal, one.stages[0].value
    later = fmm.travel_time(0.8 * v, g.spacing, fmm.point_source(g, z, 0.8 * v) + t1, ceiling=one.capture_time)
    concatenated = later[flag].min()
    assert math.isfinite(two.value) and two.value <= concatenated + 1e-9
    assert_path_is_safe_and_consistent(two, xa, [bar, flag], [v, 0.8 * v])


def obstacle_course():
    g = Grid.covering((0.0, 0.0), (60.0, 40.0), 0.5)
    x, y = g.mesh()
    terrain = np.full(g.shape, 0.5)
    terrain[(y >= 30) & (y <= 33)] = 1.0  # a fast walkway along the north
    blocks = [(15, 25, 0, 24), (35, 45, 12, 40 - 12)]
    for x0, x1, y0, y1 in blocks:
        terrain[(x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)] = 0.0
    return g, terrain, blocks


def test_path_avoids_obstacles_and_takes_the_fast_walkway():
    g, terrain, blocks = obstacle_course()
    x, y = g.mesh()
    speeds = [4 * terrain, 2 * terrain]
    flag = disk((x, y), (55, 5), 2.0)
    home = disk((x, y), (5, 36), 2.0)
    xa = (3.0, 3.0)
    sol = solve_openloop(g, xa, speeds, [flag, home], [Defender((58.0, 38.0), 0.5 * terrain, 1.0)])
    assert_path_is_safe_and_consistent(sol, xa, [flag, home], speeds)
    h = g.spacing[0]
    px, py = sol.path.points.T
    for x0, x1, y0, y1 in blocks:
        inside = (px > x0 + h / 2) & (px < x1 - h / 2) & (py > y0 + h / 2) & (py < y1 - h / 2)
        assert not inside.any()
    # Stage 1 goes over the first block on the walkway, which is faster than the
    # slow ground below even though longer.
    first = sol.path.points[: sol.path.stage_starts[1]]
    on_walkway = (first[:, 1] >= 30) & (first[:, 1] <= 33)
    assert on_walkway.sum() * 0.5 * h > 10.0


def test_attacker_inside_capture_radius_is_blocked_at_once():
    g, v, mesh = open_square(side=20.0, h=0.5)
    sol = solve_openloop(
        g, (5.0, 5.0), [v, v], [disk(mesh, (15, 15), 2), disk(mesh, (2, 18), 1)], [Defender((6.0, 5.0), v, 2.0)]
    )
    assert not sol.reached and sol.blocked_stage == 0 and sol.path is None
    assert sol.value == math.inf
    assert not sol.stages[0].safe.any() and sol.stages[0].safe_area == 0.0
    assert sol.stages[1].value == math.inf and sol.stages[1].goal is None


def test_defender_on_top_of_the_attacker_captures_at_once_between_nodes():
    """A slow defender starting on the attacker, with a radius under a cell: the
    attacker is captured at t = 0 although it could outrun it to every node."""
    g, v, mesh = open_square(side=20.0, h=0.5)
    sol = solve_openloop(g, (12.3, 7.1), [3 * v], [disk(mesh, (2, 18), 1)], [Defender((12.4, 7.1), 0.5 * v, 0.2)])
    assert sol.blocked_stage == 0 and sol.path is None and not sol.stages[0].safe.any()


def test_second_target_guarded_blocks_stage_two_only():
    g, v, mesh = open_square(side=20.0, h=0.5)
    sol = solve_openloop(
        g,
        (2.0, 2.0),
        [2 * v, 2 * v],
        [disk(mesh, (6, 3), 1), disk(mesh, (17, 17), 1)],
        [Defender((17.0, 16.0), v, 2.5)],
    )
    assert sol.blocked_stage == 1 and sol.path is None
    assert math.isfinite(sol.stages[0].value) and sol.stages[0].goal is not None
    assert sol.stages[1].value == math.inf


@settings(max_examples=15, deadline=None)
@given(
    xa=st.tuples(st.floats(1, 19), st.floats(1, 19)),
    xd=st.tuples(st.floats(1, 19), st.floats(1, 19)),
    ratio=st.floats(0.5, 3.0),
    radius=st.floats(0.0, 2.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_random_games_keep_the_invariants(xa, xd, ratio, radius, seed):
    rng = np.random.default_rng(seed)
    g = Grid.covering((0.0, 0.0), (20.0, 20.0), 0.5)
    x, y = g.mesh()
    terrain = rng.choice([0.4, 0.7, 1.0], size=g.shape)
    target = disk((x, y), rng.uniform(2, 18, 2), 1.5)
    assume(math.dist(xa, xd) >= 1.0)
    sol = solve_openloop(g, xa, [ratio * terrain], [target], [Defender(xd, terrain, radius)])
    stage = sol.stages[0]
    np.testing.assert_array_equal(stage.safe, np.isfinite(stage.phi))
    assert np.all(stage.phi[stage.safe] < sol.capture_time[stage.safe])
    assert stage.value == (stage.phi[target].min() if stage.safe[target].any() else math.inf)
    if sol.reached:
        # Node-by-node random terrain has no meaningful speed between nodes.
        assert_path_is_safe_and_consistent(sol, xa, [target], [ratio * terrain], walk_tolerance=None)


def game(**change):
    g = Grid.covering((0.0, 0.0), (10.0, 10.0), 0.5)
    v = np.ones(g.shape)
    v[10, 10] = 0.0
    target = np.zeros(g.shape, bool)
    target[18, 18] = True
    args = dict(
        grid=g,
        attacker=(1.0, 1.0),
        stage_speeds=[v],
        targets=[target],
        defenders=[Defender((9.0, 1.0), v, 0.5)],
    )
    args.update(change)
    return args


ONES = np.ones((21, 21))
HOLE = np.ones((21, 21))
HOLE[10, 10] = 0.0  # the node at (5 m, 5 m)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(attacker=(float("nan"), 1.0)), r"attacker position \(nan, 1\) is not a finite"),
        (dict(attacker=(12.0, 1.0)), r"attacker at \(12, 1\) lies outside the grid"),
        (dict(attacker=(5.0, 5.0)), r"attacker at \(5, 5\) is on an impassable node \(speed 0\)"),
        (dict(defenders=[Defender((5.0, 5.1), HOLE)]), r"defender 1 at \(5, 5.1\) is on an impassable node"),
        (dict(defenders=[Defender((1.0, 9.0), ONES), Defender((-3.0, 1.0), ONES)]), "defender 2 at .* outside"),
        (dict(defenders=[Defender((9.0, 1.0), -ONES)]), "defender 1 speed has a negative, NaN or infinite value"),
        (dict(defenders=[Defender((9.0, 1.0), ONES * np.nan)]), "defender 1 speed has a negative, NaN or infinite"),
        (dict(defenders=[Defender((9.0, 1.0), np.ones((3, 3)))]), r"defender 1 speed has shape \(3, 3\)"),
        (dict(defenders=[Defender((9.0, 1.0), ONES, -1.0)]), "defender 1 capture radius"),
        (dict(defenders=[Defender((9.0, 1.0), ONES, float("nan"))]), "defender 1 capture radius"),
        (dict(stage_speeds=[ONES * np.nan]), "stage 1 speed has a negative, NaN or infinite value"),
        (dict(stage_speeds=[ONES * np.inf]), "stage 1 speed has a negative, NaN or infinite value"),
        (dict(grid=Grid.covering((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 0.5)), "2-D grid"),
        (dict(stage_speeds=[np.ones((4, 4))]), r"stage 1 speed has shape \(4, 4\)"),
        (dict(stage_speeds=[ONES, ONES]), "2 stage speed maps for 1 targets"),
        (dict(targets=[np.zeros((21, 21), bool)]), "target 1 is empty"),
        (dict(targets=[np.ones((5, 5), bool)]), r"target 1 has shape \(5, 5\)"),
        (dict(targets=[], stage_speeds=[]), "at least one target"),
        (dict(order=3), "order must be 1 or 2"),
    ],
)
def test_bad_input_names_the_culprit(change, message):
    with pytest.raises(InputError, match=message):
        solve_openloop(**game(**change))
