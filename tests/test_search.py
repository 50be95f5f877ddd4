"""Reachability-guided UAV search (thesis 6.2): line of sight against exact
shadows, the growth of P_D against disks and walls, the P_D invariant on
random evading defenders, and the target hierarchy on constructed cases."""

import math

import numpy as np
import pytest
import shapely
from scipy import ndimage
from shapely.geometry import box

from bearcat.solvers.errors import InputError
from bearcat.solvers.grid import Grid
from bearcat.solvers.search import (
    PossibleDefender,
    Weights,
    footprint,
    lawnmower,
    nearest_unobserved,
    search_target,
    visibility,
)

H = 1.0
BUILDINGS = [(20, 15, 45, 35), (60, 40, 85, 65), (15, 50, 35, 70)]


def field(width=100.0, height=80.0, buildings=()):
    """A grid at H over the box and its free mask; buildings are (xmin, ymin,
    xmax, ymax) boxes whose edges are free, as in the map model."""
    grid = Grid.covering((0.0, 0.0), (width, height), H)
    x, y = grid.mesh()
    free = np.ones(grid.shape, dtype=bool)
    for x0, y0, x1, y1 in buildings:
        free &= ~((x > x0) & (x < x1) & (y > y0) & (y < y1))
    return grid, free


def nodes(grid):
    x, y = grid.mesh()
    return np.column_stack([x.ravel(), y.ravel()])


# --------------------------------------------------------------------------- visibility


def test_an_open_field_is_all_visible_and_range_cuts_a_disk():
    grid, free = field()
    for viewer in [(0.0, 0.0), (37.3, 61.8), (100.0, 80.0)]:
        assert visibility(free, grid, viewer).all()
    x, y = grid.mesh()
    near = visibility(free, grid, (37.3, 61.8), max_range=20.0)
    assert np.array_equal(near, np.hypot(x - 37.3, y - 61.8) <= 20.0)


@pytest.mark.parametrize("viewer", [(20.3, 50.6), (15.0, 15.0), (50.2, 88.0), (64.0, 30.5)])
def test_the_shadow_of_a_square_building_is_exactly_not_visible(viewer):
    building = (40.0, 40.0, 60.0, 60.0)
    grid, free = field(100.0, 100.0, [building])
    seen = visibility(free, grid, viewer)
    lines = shapely.linestrings([[viewer, tuple(p)] for p in nodes(grid)])
    # One cell either side of the building's edge is the raster's slack.
    hidden = shapely.intersects(lines, box(*building).buffer(-H, join_style="mitre")).reshape(grid.shape)
    clear = ~shapely.intersects(lines, box(*building).buffer(H)).reshape(grid.shape)
    assert hidden.sum() > 300 and clear.sum() > 5000, "the case must have a real shadow"
    assert not (seen & hidden).any()
    assert seen[clear & free].all()
    assert not seen[~free].any()


def test_line_of_sight_has_no_preferred_direction():
    """Mirroring or transposing the map and the viewer does the same to what is seen."""
    grid, free = field(100.0, 80.0, BUILDINGS)
    flipped = Grid(grid.lo, grid.spacing, grid.shape[::-1])
    for x, y in [(10.3, 44.1), (52.71, 38.23), (90.1, 7.7)]:
        seen = visibility(free, grid, (x, y))
        assert 1000 < seen.sum() < free.sum()
        assert np.array_equal(visibility(free[::-1], grid, (100 - x, y))[::-1], seen)
        assert np.array_equal(visibility(free[:, ::-1], grid, (x, 80 - y))[:, ::-1], seen)
        assert np.array_equal(visibility(free.T, flipped, (y, x)).T, seen)


def test_a_thin_wall_hides_what_is_behind_it_from_a_viewer_close_in_front():
    grid, free = field(buildings=[(40.0, 20.0, 43.0, 60.0)])  # nodes x = 41, 42 inside
    seen = visibility(free, grid, (38.6, 40.0))
    assert seen[:41, 20:61].all() and not seen[43:, 35:46].any()


def test_a_viewer_sees_out_of_a_fix_just_inside_a_wall():
    grid, free = field(buildings=[(40.0, 20.0, 60.0, 60.0)])
    assert visibility(free, grid, (40.4, 40.0))[:30].all()


def test_footprint_is_the_disk_and_may_hang_off_the_grid():
    grid, _ = field()
    x, y = grid.mesh()
    assert np.array_equal(footprint(grid, (30.5, 20.2), 12.0), np.hypot(x - 30.5, y - 20.2) <= 12.0)
    off = footprint(grid, (-10.0, 40.0), 12.0)
    assert off.any() and not off[3:].any()


def test_visibility_refuses_a_viewer_off_the_grid():
    grid, free = field()
    with pytest.raises(InputError, match=r"viewer at \(120, 5\) is off the grid"):
        visibility(free, grid, (120.0, 5.0))


# --------------------------------------------------------------------------- P_D


@pytest.mark.parametrize("dt", [0.1, 0.5, 2.0])
def test_possible_positions_grow_at_the_defender_speed_on_an_open_field(dt):
    """0.2 m a step at 0.1 s is a fifth of a cell: growth must add up across steps."""
    grid, free = field(100.0, 100.0)
    center, r0, v_d, duration = (50.3, 49.6), 10.0, 2.0, 12.0
    pd = PossibleDefender.around(free, grid, center, r0)
    nothing = np.zeros(grid.shape, dtype=bool)
    for _ in range(round(duration / dt)):
        pd.advance(dt, v_d, nothing)
    r = r0 + v_d * duration
    assert math.pi * (r - H) ** 2 <= pd.area <= math.pi * (r + H) ** 2
    x, y = grid.mesh()
    distance = np.hypot(x - center[0], y - center[1])
    assert pd.mask[distance <= r - H].all() and not pd.mask[distance > r + H].any()


def test_possible_positions_do_not_leak_into_a_closed_room():
    walls = [(40, 30, 70, 33), (40, 57, 70, 60), (40, 30, 43, 60), (67, 30, 70, 60)]  # two nodes thick
    grid, free = field(buildings=walls)
    x, y = grid.mesh()
    inside = (x >= 43) & (x <= 67) & (y >= 33) & (y <= 57)  # inner faces included
    pd = PossibleDefender.around(free, grid, (10.0, 10.0), 3.0)
    for _ in range(20):
        pd.advance(5.0, 3.0, np.zeros(grid.shape, dtype=bool))
    assert pd.mask[free & ~inside].all() and not pd.mask[inside].any()


def test_possible_positions_go_round_a_wall_no_faster_than_the_defender():
    grid, free = field(buildings=[(49, -1, 51, 70)])
    pd = PossibleDefender.around(free, grid, (30.0, 10.0), 0.0)
    behind = grid.nearest_index((70.0, 10.0))
    nothing = np.zeros(grid.shape, dtype=bool)
    # The walk round the wall's end at (50, 70) is 126.5 m; straight through it, 40 m.
    for _ in range(120):
        pd.advance(1.0, 1.0, nothing)
    assert not pd.mask[behind]
    for _ in range(12):
        pd.advance(1.0, 1.0, nothing)
    assert pd.mask[behind]


def test_found_collapses_onto_the_seen_position():
    grid, free = field()
    pd = PossibleDefender(free, grid, free)
    pd.found((30.4, 20.7))
    assert pd.mask.sum() <= 9 and pd.mask[grid.nearest_index((30.4, 20.7))]


def segment_is_free(a, b):
    """The straight walk a -> b stays out of every building's interior."""
    t = np.linspace(0.0, 1.0, 60)[:, None]
    p = a + t * (b - a)
    inside = [(p[:, 0] > x0) & (p[:, 0] < x1) & (p[:, 1] > y0) & (p[:, 1] < y1) for x0, y0, x1, y1 in BUILDINGS]
    return (p >= 0).all() and (p[:, 0] <= 100).all() and (p[:, 1] <= 80).all() and not np.any(inside)


def along(path, distance):
    """The point ``distance`` metres along the closed tour of ``path``."""
    tour = np.vstack([path, path[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(tour, axis=0).T))])
    d = distance % s[-1]
    return np.array([np.interp(d, s, tour[:, 0]), np.interp(d, s, tour[:, 1])])


@pytest.mark.parametrize(("seed", "dt", "v_d"), [(0, 0.5, 3.0), (1, 0.5, 3.0), (2, 0.2, 2.0), (3, 1.0, 5.0)])
def test_the_defender_is_always_possible_and_never_where_it_is_seen(seed, dt, v_d):
    """A defender walks at top speed, turning at random and whenever its next
    step would end seen or cross a wall; the attacker patrols and the UAV
    sweeps. Every tick: P_D and V_J are disjoint, and an unseen defender is
    within one cell of P_D."""
    rng = np.random.default_rng(seed)
    grid, free = field(buildings=BUILDINGS)
    r_q = 8.0
    patrol = np.array([[10.0, 5.0], [55.0, 5.0], [55.0, 30.0], [10.0, 30.0]])
    sweep = lawnmower((0, 0, 100, 80), r_q)
    defender = np.array([90.0, 75.0])
    pd = PossibleDefender.around(free, grid, defender, 2.0)
    heading = rng.uniform(0, 2 * math.pi)
    unseen_ticks = found = 0
    ticks = round(120 / dt)
    for tick in range(ticks):
        t = tick * dt
        attacker, uav = along(patrol, 1.5 * t), along(sweep, 10 * t)
        seen = visibility(free, grid, attacker, max_range=40.0) | footprint(grid, uav, r_q)
        for _ in range(12):
            step = defender + v_d * dt * np.array([math.cos(heading), math.sin(heading)])
            if segment_is_free(defender, step) and not seen[grid.nearest_index(step)]:
                defender = step
                break
            heading = rng.uniform(0, 2 * math.pi)
        pd.advance(dt, v_d, seen)
        assert not (pd.mask & seen).any(), f"P_D overlaps V_J at t = {t}"
        if seen[grid.nearest_index(defender)]:
            pd.found(defender)
            found += 1
        else:
            unseen_ticks += 1
        near = ndimage.binary_dilation(pd.mask, np.ones((3, 3), dtype=bool))
        assert near[grid.nearest_index(defender)], f"the defender at {defender} escaped P_D at t = {t}"
    assert unseen_ticks > ticks / 2 and found > 0, "the run must test both growth and collapse"


def test_a_defender_may_dash_across_a_seen_band_narrower_than_a_step():
    """Sensing is sampled: a defender unseen at both ticks may cross a band
    seen at both, if it is narrower than its step (module notes)."""
    grid, free = field()
    x, _ = grid.mesh()
    band = (x >= 50) & (x <= 51)
    pd = PossibleDefender(free, grid, x < 50)
    pd.advance(1.0, 3.0, band)
    assert pd.mask[(x > 51) & (x <= 52.9)].all() and not pd.mask[x >= 53.1].any()


def test_a_found_defender_may_step_out_of_view():
    grid, free = field()
    x, _ = grid.mesh()
    seen = x <= 50  # the defender was seen at (48, 40) and is still in view ...
    pd = PossibleDefender(free, grid, free, seen=seen)
    pd.found((48.0, 40.0))
    pd.advance(1.0, 4.0, seen)
    assert pd.mask[grid.nearest_index((51.0, 40.0))]  # ... unless it has stepped out of it


def test_possible_defender_refuses_bad_steps():
    grid, free = field()
    pd = PossibleDefender(free, grid, free)
    with pytest.raises(InputError, match="defender speed must be a positive finite number"):
        pd.advance(1.0, 0.0, free)
    with pytest.raises(InputError, match=r"seen has shape \(3, 3\) but the grid has shape \(101, 81\)"):
        pd.advance(1.0, 1.0, np.zeros((3, 3), dtype=bool))


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda grid, free: visibility(free, grid, (5.0, 5.0), max_range=-1.0), "max_range must be a number >= 0"),
        (lambda grid, free: visibility(free, grid, (5.0, 5.0), max_range="far"), "max_range must be a number >= 0"),
        (lambda grid, free: Weights(uav="100"), "weight uav must be a finite number >= 0, got '100'"),
        (lambda grid, free: lawnmower((0, 0, 10, 10), 0.0), "footprint radius must be a positive finite number"),
    ],
)
def test_number_checks_name_the_argument(call, message):
    grid, free = field()
    with pytest.raises(InputError, match=message):
        call(grid, free)


def test_visibility_without_a_range_limit_sees_as_far_as_the_walls():
    grid, free = field()
    assert np.array_equal(visibility(free, grid, (5.0, 5.0)), visibility(free, grid, (5.0, 5.0), max_range=1e9))


# --------------------------------------------------------------------------- the target


SPEEDS = dict(defender_speed=2.0, uav_speed=2.0, uav_radius=0.0)


def strip_case(win_band):
    """60 x 40 m, no buildings. The attacker sees the west (x <= 20); the
    defender may be in a disk in the east; W_D is ``x`` in ``win_band``."""
    grid = Grid.covering((0.0, 0.0), (60.0, 40.0), H)
    x, y = grid.mesh()
    terrain = np.ones(grid.shape)
    seen_attacker = x <= 20
    possible = np.hypot(x - 50, y - 20) <= 5
    defender_wins = (x >= win_band[0]) & (x <= win_band[1])
    return grid, terrain, possible, seen_attacker, defender_wins


def target_for(case, uav=(50.0, 0.0), seen_uav=None, weights=None, attacker=(5.0, 20.0), **speeds):
    grid, terrain, possible, seen_attacker, defender_wins = case
    if seen_uav is None:
        seen_uav = np.zeros(grid.shape, dtype=bool)
    return search_target(
        terrain,
        grid,
        possible,
        seen_attacker,
        seen_uav,
        defender_wins,
        attacker=attacker,
        uav=uav,
        weights=weights or Weights(),
        **(SPEEDS | speeds),
    )


def in_candidates(result, grid):
    return bool(result.candidates[grid.nearest_index(result.target)])


def test_tier_1_when_a_possible_defender_can_reach_the_visible_winning_set_unseen():
    case = strip_case((10, 20))
    result = target_for(case)
    assert result.tier == 1 and result.z.any() and not result.z_tilde.any()
    assert np.array_equal(result.candidates, result.s_d & result.reach_z) and in_candidates(result, case[0])


def test_tier_2_when_the_visible_winning_set_lies_behind_seen_ground():
    case = strip_case((5, 30))
    x, _ = case[0].mesh()
    assert target_for(case).tier == 1  # Z borders the unseen east ...
    sealed = target_for(case, seen_uav=(x > 20) & (x < 24))  # ... until the UAV watches a band between
    assert sealed.tier == 2 and sealed.z.any() and sealed.z_tilde.any()
    assert not (sealed.s_d & sealed.reach_z).any()
    assert np.array_equal(sealed.candidates, sealed.s_d & sealed.reach_z_tilde) and in_candidates(sealed, case[0])


def test_tier_3_when_no_possible_defender_can_reach_any_winning_position():
    case = strip_case((5, 15))  # W_D lies deep inside what the attacker sees
    result = target_for(case)
    assert result.tier == 3 and result.z.any() and not result.z_tilde.any()
    assert np.array_equal(result.candidates, result.s_d) and in_candidates(result, case[0])


def test_nothing_to_search_when_p_d_is_empty():
    grid, terrain, _, seen_attacker, defender_wins = strip_case((10, 20))
    result = target_for((grid, terrain, np.zeros(grid.shape, dtype=bool), seen_attacker, defender_wins))
    assert result.tier == 0 and result.target is None and not result.s_d.any()


@pytest.mark.parametrize(("r_q", "meet"), [(0.0, 35), (10.0, 40)])
def test_s_d_stops_where_the_uav_would_see_the_defender_first(r_q, meet):
    """Equal speeds: S_D is what the defender, leaving P_D (x >= 55), reaches
    before the UAV at x = 15 brings it within r_q: x > (55 + 15 + r_q) / 2."""
    grid, terrain, _, _, defender_wins = strip_case((10, 20))
    x, _ = grid.mesh()
    nothing = np.zeros(grid.shape, dtype=bool)
    result = target_for((grid, terrain, x >= 55, nothing, defender_wins), uav=(15.0, 20.0), uav_radius=r_q)
    row = result.s_d[:, round(20 / H)]
    assert row[round((meet + 1) / H) :].all() and not row[: round(meet / H) + 1].any()


def test_a_heavy_uav_weight_picks_the_candidate_nearest_the_uav():
    case = strip_case((10, 20))
    grid = case[0]
    x, y = grid.mesh()
    for uav in [(50.0, 0.0), (60.0, 40.0), (30.0, 35.0)]:
        result = target_for(case, uav=uav, weights=Weights(uav=1e6))
        distance = np.hypot(x - uav[0], y - uav[1])
        assert math.hypot(result.target[0] - uav[0], result.target[1] - uav[1]) == pytest.approx(
            distance[result.candidates].min()
        )


def test_zero_uav_weight_trades_distance_to_z_against_distance_to_the_attacker():
    result = target_for(strip_case((10, 20)), weights=Weights(uav=0.0))
    # A candidate at (x, y) has psi_Z + psi_delta >= (x - 20) + (x - 5): the
    # first unseen node on the attacker's row is best.
    assert result.target == pytest.approx((21.0, 20.0), abs=H)


# --------------------------------------------------------------------------- baselines


@pytest.mark.parametrize(("bounds", "r_q"), [((0, 0, 250, 200), 15.0), ((10, -5, 40, 95), 7.0), ((0, 0, 20, 20), 30.0)])
def test_the_lawnmower_covers_the_box(bounds, r_q):
    path = lawnmower(bounds, r_q, start=(bounds[2], bounds[3]))
    assert np.hypot(*(path[0] - bounds[2:])) <= r_q * math.sqrt(2) + 1e-9
    sweep = shapely.LineString(path).buffer(r_q * (1 + 1e-6))
    assert sweep.covers(box(*bounds))
    tracks = np.unique(path[:, 0] if bounds[3] - bounds[1] > bounds[2] - bounds[0] else path[:, 1])
    assert np.all(np.diff(tracks) <= 2 * r_q + 1e-9)


def test_nearest_unobserved_is_the_nearest_possible_node():
    grid, _ = field()
    x, y = grid.mesh()
    possible = (np.hypot(x - 70, y - 40) <= 10) | (np.hypot(x - 20, y - 60) <= 3)
    assert nearest_unobserved(grid, possible, (0.0, 0.0)) == (20.0, 57.0)  # 60.4 m; (19, 58) is 61.0 m
    assert nearest_unobserved(grid, possible, (100.0, 40.0)) == (80.0, 40.0)
    assert nearest_unobserved(grid, np.zeros(grid.shape, dtype=bool), (0.0, 0.0)) is None
