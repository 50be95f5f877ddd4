"""The HJI reach-avoid solver against sets known by inspection, by geometry
and in closed form; monotonicity, grid edges, convergence, T*, bad input."""

import tracemalloc

import numba
import numpy as np
import pytest

from bearcat.solvers.errors import InputError
from bearcat.solvers.grid import Grid
from bearcat.solvers.levelset import kernels as kern
from bearcat.solvers.levelset.hamiltonians import Ball, Box, ControlAffine, Player, SimpleMotion
from bearcat.solvers.levelset.hji import PaddedField, required_bytes, solve_reach_avoid
from tests.support.flag_return import STRIP, far_from_boundary, flag_return, flag_return_by_geometry
from tests.support.local_band import assert_local_matches_full

SCHEMES = ("first", "weno5")
# Half-width, in cells, of the band around a set boundary where the schemes
# may disagree with the exact set: first order rounds the corners of a set
# by up to about three cells once the front has travelled far.
BAND = {"first": 3.5, "weno5": 1.5}


def assert_matches(found, exact, cells):
    far = far_from_boundary(exact, cells)
    assert far.sum() > 0.5 * exact.size
    wrong = np.argwhere((found != exact) & far)
    assert len(wrong) == 0, f"{len(wrong)} nodes disagree, e.g. {wrong[:3].tolist()}"


# --- the 1-D game of thesis Fig. 3.2: joint space (x_a, x_d) on [-5, 5] ---

FLAG = (2.0, 3.0)
HOME = -4.0  # the return region x <= -4 touches the edge of the area
CAPTURE = 0.5


def interval_distance(x, lo, hi):
    return np.maximum(lo - x, x - hi)


def line_game(stage, scheme, defender_speed=1.0, capture_radius=CAPTURE, n=121):
    g = Grid.spanning((-5.0, -5.0), (5.0, 5.0), (n, n))
    xa, xd = g.mesh()
    forfeit = np.minimum(interval_distance(xd, *FLAG), xd - HOME)  # the defender in F or R
    goal = interval_distance(xa, *FLAG) if stage == "capture" else xa - HOME
    result = solve_reach_avoid(
        g,
        SimpleMotion.pursuit(1.0, defender_speed, dims=1),
        np.minimum(goal, forfeit),
        np.abs(xa - xd) - capture_radius,
        horizon=15.0,
        scheme=scheme,
    )
    return result.reach_avoid_set, xa, xd


def line_game_by_inspection(stage, xa, xd):
    """With equal speeds on a line nobody gains ground, so the attacker wins
    unless it is captured at once or the defender stands strictly between it
    and its goal; a defender beyond the flag cannot come back through it, and
    a defender in F or R has forfeited."""
    free = np.abs(xa - xd) > CAPTURE
    forfeited = ((xd >= FLAG[0]) & (xd <= FLAG[1])) | (xd <= HOME)
    if stage == "capture":
        arrived = (xa >= FLAG[0]) & (xa <= FLAG[1])
        blocked = ((xa < FLAG[0]) & (xa < xd) & (xd < FLAG[0])) | ((xa > FLAG[1]) & (FLAG[1] < xd) & (xd < xa))
    else:
        arrived = xa <= HOME
        blocked = (xd > HOME) & (xd < xa)
    return free & (arrived | forfeited | ~blocked)


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize("stage", ["capture", "return"])
def test_line_game_matches_the_sets_found_by_inspection(stage, scheme):
    found, xa, xd = line_game(stage, scheme)
    exact = line_game_by_inspection(stage, xa, xd)
    assert_matches(found, exact, BAND[scheme])
    if stage == "return":
        # R touches the edge of the area: its edge row counts as reached
        # wherever the attacker is free, and the row next to R reaches it.
        assert found[0, xd[0] > HOME + CAPTURE].all()
        assert found[13, xd[13] > xa[13, 0] + CAPTURE].all()


@pytest.mark.parametrize("scheme", SCHEMES)
def test_a_faster_defender_or_a_larger_capture_radius_never_grows_the_attackers_set(scheme):
    base, _, _ = line_game("return", scheme)
    faster, _, _ = line_game("return", scheme, defender_speed=1.3)
    wider, _, _ = line_game("return", scheme, capture_radius=0.8)
    assert not (faster & ~base).any() and (base & ~faster).sum() > 100
    assert not (wider & ~base).any() and (base & ~wider).sum() > 100


# --- flag return in an open square: x = (x_a, y_a, x_d, y_d) ---


@pytest.mark.parametrize("scheme", SCHEMES)
def test_flag_return_in_an_open_square_matches_the_geometric_reference(scheme):
    g, found = flag_return(21, scheme, 1.5)
    exact = flag_return_by_geometry(g, 1.5)
    assert 0.3 < exact.mean() < 0.9
    assert_matches(found, exact, 1.5)


def test_first_order_loses_a_one_cell_capture_radius_that_weno5_keeps():
    """At 25^4 the capture radius 0.5 is little more than a cell: WENO5 still
    finds the exact set, first-order diffusion lets the attacker slip past
    the defender from thousands of states it cannot win."""
    g, weno = flag_return(25, "weno5", 0.5)
    _, first = flag_return(25, "first", 0.5)
    exact = flag_return_by_geometry(g, 0.5)
    assert_matches(weno, exact, 1.5)
    far = far_from_boundary(exact, 1.5)
    assert ((first & ~exact) & far).sum() > 0.05 * g.size


# --- one player, sets in closed form ---


def plane(n=101, side=5.0):
    return Grid.spanning((-side, -side), (side, side), (n, n))


def runner(speed=1.0, axes=(0, 1)):
    return SimpleMotion((Player(axes, speed, "control"),))


@pytest.mark.parametrize("scheme", SCHEMES)
def test_a_target_strip_along_the_edge_is_reached_from_the_rows_next_to_it(scheme):
    g = plane()
    x, _ = g.mesh()
    found = solve_reach_avoid(g, runner(), 4.5 - x, horizon=1.0, scheme=scheme, tol=0).reach_avoid_set
    assert found[x >= 3.55].all() and not found[x <= 3.45].any()


def test_speed_maps_vary_over_the_players_own_axes():
    g = plane()
    x, y = g.mesh()
    # Twice as fast east of x = 0: the strip x >= 4 is reached within 3 from x >= -1.
    fast_east = np.where(x > 0, 2.0, 1.0)
    found = solve_reach_avoid(g, runner(fast_east), 4.0 - x, horizon=3.0, tol=0).reach_avoid_set
    assert found[x >= -0.85].all() and not found[x <= -1.15].any()
    # The same along the other axis.
    found = solve_reach_avoid(g, runner(fast_east.T), 4.0 - y, horizon=3.0, tol=0).reach_avoid_set
    assert found[y >= -0.85].all() and not found[y <= -1.15].any()
    # A map over an outer axis of a 3-D grid, beside a second player.
    g3 = Grid.spanning((-5.0,) * 3, (5.0,) * 3, (41,) * 3)
    x3 = g3.mesh()[0]
    speed = np.where(g3.axes()[0] > 0, 2.0, 1.0)
    game = SimpleMotion((Player((0,), speed), Player((1, 2), 0.5)))
    found = solve_reach_avoid(g3, game, 4.0 - x3, horizon=3.0, tol=0).reach_avoid_set
    assert found[x3 >= -0.7].all() and not found[x3 <= -1.3].any()


def test_weno5_places_a_cornered_front_closer_than_first_order():
    """Reach set of the square [-1, 1]^2 at speed 1 within 2: the square grown
    by a disk of radius 2, whose rounded corners first order smears."""
    g = plane(81)
    x, y = g.mesh()
    exact_distance = np.hypot(np.maximum(np.abs(x) - 1, 0), np.maximum(np.abs(y) - 1, 0)) - 2.0
    errors = {}
    for scheme in SCHEMES:
        found = solve_reach_avoid(
            g, runner(), np.maximum(np.abs(x), np.abs(y)) - 1, horizon=2.0, scheme=scheme, tol=0
        ).reach_avoid_set
        errors[scheme] = np.abs(exact_distance[found != (exact_distance <= 0)]).max(initial=0.0)
    h = g.spacing[0]
    assert errors["weno5"] < 0.5 * h
    assert errors["first"] > 2 * errors["weno5"]


# --- control-affine dynamics ---


@numba.njit(cache=True)
def rotating(x, f0, G, K):
    f0[0] = -x[1]
    f0[1] = x[0]
    G[0, 0], G[0, 1], G[1, 0], G[1, 1] = 1.0, 0.0, 0.0, 1.0


@numba.njit(cache=True)
def drifting_both_ways(x, f0, G, K):
    f0[0] = 0.0
    f0[1] = 0.0
    for i in range(2):
        for j in range(2):
            G[i, j] = 1.0 if i == j else 0.0
            K[i, j] = 1.0 if i == j else 0.0


@pytest.mark.parametrize("scheme", SCHEMES)
def test_control_affine_rotation_with_a_ball_of_controls(scheme):
    """x' = (-y, x) + u, |u| <= 1: in the rotating frame simple motion, so x
    reaches the disk B((2, 0), 0.5) within 1.5 iff |x - R(-t)(2, 0)| <= 0.5 + t
    for some t in [0, 1.5]."""
    g = plane()
    x, y = g.mesh()
    found = solve_reach_avoid(
        g,
        ControlAffine(rotating, control=Ball((0.0, 0.0), 1.0)),
        np.hypot(x - 2, y) - 0.5,
        horizon=1.5,
        scheme=scheme,
        tol=0,
    ).reach_avoid_set
    t = np.linspace(0, 1.5, 601)[:, None, None]
    # 1-Lipschitz, <= 0 exactly on the set: how far a node is inside or out.
    margin = (np.hypot(x - 2 * np.cos(t), y + 2 * np.sin(t)) - 0.5 - t).min(axis=0)
    wrong = found != (margin <= 0)
    assert np.abs(margin[wrong]).max(initial=0.0) < BAND[scheme] * g.spacing[0]
    assert (margin <= 0).sum() > 500 and not (margin <= 0)[y > 0.6].all()


@pytest.mark.parametrize("scheme", SCHEMES)
def test_control_affine_boxes_against_a_disturbance(scheme):
    """x' = u + d with u in [-1, 2] x [-0.5, 0.5], d in [-0.25, 0.25] x [-0.1, 0.1]:
    each axis holds its ground against the disturbance, so the box [-0.5, 0.5]^2
    is reached within 1.5 exactly from [-0.5 - 1.75 * 1.5, 0.5 + 0.75 * 1.5] x
    [-0.5 - 0.4 * 1.5, 0.5 + 0.4 * 1.5]."""
    g = plane()
    x, y = g.mesh()
    dynamics = ControlAffine(
        drifting_both_ways, control=Box((-1.0, -0.5), (2.0, 0.5)), disturbance=Box((-0.25, -0.1), (0.25, 0.1))
    )
    target = np.maximum(np.abs(x), np.abs(y)) - 0.5
    found = solve_reach_avoid(g, dynamics, target, horizon=1.5, scheme=scheme, tol=0).reach_avoid_set
    exact = (x >= -3.125) & (x <= 1.625) & (np.abs(y) <= 1.1)
    assert_matches(found, exact, BAND[scheme])


def test_dynamics_that_leave_entries_unset_are_refused():
    g = plane(11)
    x, _ = g.mesh()
    with pytest.raises(InputError, match="K"):
        solve_reach_avoid(
            g, ControlAffine(rotating, control=Ball((0.0, 0.0), 1.0), disturbance=Ball((0.0, 0.0), 0.5)), x, horizon=1.0
        )


# --- convergence, T*, progress ---


def test_convergence_stops_a_settled_problem_and_a_short_horizon_is_not_converged():
    g = plane()
    x, y = g.mesh()
    disk = np.hypot(x, y) - 1
    calls = []
    settled = solve_reach_avoid(g, runner(), disk, horizon=20.0, tol=1e-3, progress=lambda t, c: calls.append((t, c)))
    # Every corner can reach the disk after sqrt(50) - 1 = 6.07, and the last
    # ripples settle soon after.
    assert settled.converged and 6.0 < settled.converged_at <= 9.0
    assert settled.time == settled.converged_at and settled.reach_avoid_set.all()
    assert [t for t, _ in calls] == sorted(t for t, _ in calls) and calls[-1][0] == settled.time
    assert calls[-1][1] < 1e-3 <= calls[0][1]
    short = solve_reach_avoid(g, runner(), disk, horizon=2.0, tol=1e-3)
    assert not short.converged and short.converged_at is None and short.time == pytest.approx(2.0)


def test_tstar_records_when_and_with_which_gradient_the_front_passed():
    g = plane()
    x, y = g.mesh()
    r = np.hypot(x, y)
    result = solve_reach_avoid(g, runner(), r - 1, horizon=3.0, tol=0, record_tstar=True)
    ring = (r > 1.3) & (r < 3.7)
    assert np.abs(result.tstar[ring] - (r[ring] - 1)).max() < 0.1
    assert (result.tstar[r <= 0.95] == 0).all() and np.isinf(result.tstar[r > 4.2]).all()
    grad = result.tstar_gradient[ring]
    radial = np.stack([x[ring], y[ring]], axis=-1) / r[ring][:, None]
    cosine = (grad * radial).sum(axis=-1) / np.linalg.norm(grad, axis=-1)
    assert cosine.min() > 0.95


# --- bad input ---


def test_a_grid_too_large_for_memory_is_refused_before_allocating():
    g = Grid.spanning((0.0,) * 4, (1.0,) * 4, (200,) * 4)
    lazy = np.broadcast_to(np.float32(1.0), g.shape)
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match=r"grid 200x200x200x200 .* needs about \d+\.\d+ GB"):
            solve_reach_avoid(g, SimpleMotion.pursuit(1.0, 1.0), lazy, lazy, horizon=1.0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 10e6
    assert required_bytes(g) > 30e9


def test_bad_inputs_name_the_culprit():
    g = plane(11)
    x, _ = g.mesh()
    bad = x.copy()
    bad[3, 4] = np.nan
    with pytest.raises(InputError, match=r"target .* NaN at node \(3, 4\)"):
        solve_reach_avoid(g, runner(), bad, horizon=1.0)
    with pytest.raises(InputError, match=r"avoid has shape \(11, 10\)"):
        solve_reach_avoid(g, runner(), x, x[:, :10], horizon=1.0)
    with pytest.raises(InputError, match="speed map has shape"):
        solve_reach_avoid(g, runner(np.ones((10, 11))), x, horizon=1.0)
    with pytest.raises(InputError, match="scheme"):
        solve_reach_avoid(g, runner(), x, horizon=1.0, scheme="eno3")
    with pytest.raises(InputError, match="axis 1 belongs"):
        solve_reach_avoid(g, SimpleMotion((Player((0, 1), 1.0), Player((1,), 1.0))), x, horizon=1.0)
    with pytest.raises(InputError, match="horizon"):
        solve_reach_avoid(g, runner(), x, horizon=-1.0)


def test_padded_fields_solve_exactly_like_plain_arrays_and_tstar_can_skip_the_gradient():
    g = Grid.spanning((-5.0,) * 4, (5.0,) * 4, (9,) * 4)
    xa, ya, xd, yd = g.mesh()
    target, avoid = np.minimum(4.0 - xa, 4.0 - xd), np.hypot(xa - xd, ya - yd) - 1.5
    plain = solve_reach_avoid(g, SimpleMotion.pursuit(1.0, 1.0), target, avoid, horizon=3.0, record_tstar=True)
    fields = []
    for array in (target, avoid):
        field = PaddedField(g)
        field.nodes[...] = array
        fields.append(field)
    padded = solve_reach_avoid(
        g, SimpleMotion.pursuit(1.0, 1.0), *fields, horizon=3.0, record_tstar=True, record_gradient=False
    )
    assert np.array_equal(plain.value, padded.value) and np.array_equal(plain.tstar, padded.tstar)
    assert padded.tstar_gradient is None and plain.tstar_gradient is not None
    with pytest.raises(InputError, match="PaddedField"):
        solve_reach_avoid(g, SimpleMotion.pursuit(1.0, 1.0), PaddedField(g, np.float64), horizon=1.0)


def test_a_five_dimensional_grid_grows_a_ball_at_the_runners_speed_whatever_the_other_player_does():
    """A 3-D runner (axes 0-2) and an irrelevant 2-D disturbance (axes 3-4):
    the set after time t is the ball of radius 1.5 + t, on every 2-D slice."""
    g = Grid.spanning((-5.0,) * 5, (5.0,) * 5, (11,) * 5)
    x = g.mesh()
    radius = np.sqrt(x[0] ** 2 + x[1] ** 2 + x[2] ** 2)
    game = SimpleMotion((Player((0, 1, 2), 1.0, "control"), Player((3, 4), 0.5, "disturbance")))
    found = solve_reach_avoid(g, game, radius - 1.5, horizon=2.0).reach_avoid_set
    assert_matches(found, radius <= 3.5, 1.0)


def _single_rows(shape):
    """Blocks of one row each: the shortest blocks a band can make."""
    na = shape[-2]
    planes = int(np.prod(shape[:-2]))
    return np.array([(p, i, 1) for p in range(planes) for i in range(na)], np.int64)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_a_stage_over_single_rows_computes_exactly_what_one_over_whole_planes_does(scheme, monkeypatch):
    """The stage kernel takes blocks of rows; cut into single rows, a solve
    (4-D simple motion with T* and its gradient, and a 2-D affine one)
    gives the same numbers, bit for bit, as one block per plane."""
    g = Grid.spanning((-5.0,) * 4, (5.0,) * 4, (11,) * 4)
    xa, ya, xd, yd = np.meshgrid(*g.axes(), indexing="ij", sparse=True)
    target = np.broadcast_to(np.minimum(STRIP - xa, STRIP - xd), g.shape)
    avoid = np.hypot(xa - xd, ya - yd) - 1.5
    flat = plane()
    x, y = flat.mesh()

    def solves():
        game = solve_reach_avoid(
            g, SimpleMotion.pursuit(1.0, 1.0), target, avoid, horizon=3.0, scheme=scheme, record_tstar=True, tol=0
        )
        turn = solve_reach_avoid(
            flat, ControlAffine(rotating, control=Ball((0.0, 0.0), 1.0)), np.hypot(x - 2, y) - 0.5, horizon=1.0
        )
        return game.value, game.tstar, game.tstar_gradient, turn.value

    whole = solves()
    monkeypatch.setattr(kern, "plane_blocks", _single_rows)
    rows = solves()
    for a, b in zip(whole, rows):
        assert np.array_equal(a, b)


# --- the local (narrow-band) solve ---


def assert_local_matches(full, local, cell):
    """Sets and T* as ``assert_local_matches_full`` asks, for values that
    rise by about a cell's width per cell (distances)."""
    assert local.local and not full.local
    return assert_local_matches_full(full.value, local.value, full.tstar, local.tstar, full.time / full.steps, cell / 4)


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize("stage", ["capture", "return"])
def test_the_local_solve_of_the_line_game_matches_the_full_grid(stage, scheme):
    """Fig. 3.2's game on the (x_a, x_d) plane, whose capture strip is a
    ridge of ``-g`` above the clamp the band would otherwise choose."""
    g = Grid.spanning((-5.0, -5.0), (5.0, 5.0), (121, 121))
    xa, xd = g.mesh()
    forfeit = np.minimum(interval_distance(xd, *FLAG), xd - HOME)
    goal = interval_distance(xa, *FLAG) if stage == "capture" else xa - HOME
    solves = [
        solve_reach_avoid(
            g,
            SimpleMotion.pursuit(1.0, 1.0, dims=1),
            np.minimum(goal, forfeit),
            np.abs(xa - xd) - CAPTURE,
            horizon=15.0,
            scheme=scheme,
            record_tstar=True,
            local=local,
        )
        for local in (False, True)
    ]
    assert_local_matches(*solves, g.spacing[0])
    band = {"first": 10, "weno5": 5}[scheme]  # rows, and cells of rise
    assert solves[1].ceiling == pytest.approx(max(band * g.spacing[0], CAPTURE), rel=1e-3)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_a_local_solve_updates_only_a_band_around_a_growing_ball(scheme):
    """Two runners of speed 1 on a 4-D grid: the set after time t is the
    ball of radius 1 + t sqrt(2) ... reached by both at once, and the band
    around its front is a small part of the grid, so the local solve does a
    fraction of the full grid's work for the same set and T*."""
    g = Grid.spanning((-6.0,) * 4, (6.0,) * 4, (33,) * 4)
    radius = np.sqrt(sum(x**2 for x in g.mesh()))
    game = SimpleMotion((Player((0, 1), 1.0, "control"), Player((2, 3), 1.0, "control")))
    full, local = (
        solve_reach_avoid(g, game, radius - 1.0, horizon=1.0, scheme=scheme, record_tstar=True, tol=0, local=local)
        for local in (False, True)
    )
    cell = g.spacing[0]
    assert_local_matches(full, local, cell)
    assert full.node_updates == g.size * full.steps
    assert local.node_updates < {"first": 0.7, "weno5": 0.35}[scheme] * full.node_updates  # a wider band
    # Above the set the value is the full grid's near the front, the
    # ceiling a few cells of rise out, and the ceiling beyond: the far
    # corners hold it.
    assert 2 * cell < local.ceiling <= {"first": 10, "weno5": 5}[scheme] * cell
    near = (full.value > 0) & (full.value < local.ceiling / 2)
    assert np.abs(local.value - full.value)[near].max() < 0.05 * cell
    assert local.value.max() == pytest.approx(local.ceiling)
    assert local.value[0, 0, 0, 0] == pytest.approx(local.ceiling) and full.value[0, 0, 0, 0] > 2 * local.ceiling


@pytest.mark.parametrize("scheme", SCHEMES)
def test_a_long_local_solve_keeps_pace_with_the_full_grid(scheme):
    """The open-square flag return of ``benchmarks/hji.py`` over 20 s on
    21^4: the front crosses the square twice over, through values the band
    reached long after the solve began. Left unclamped, those stood as far
    above the full grid's as the front had come, and T* lagged by 3 steps
    (first order) to 66 (WENO5)."""
    g = Grid.spanning((-5.0,) * 4, (5.0,) * 4, (21,) * 4)
    xa, ya, xd, yd = g.mesh()
    target, avoid = np.minimum(4.0 - xa, 4.0 - xd), np.hypot(xa - xd, ya - yd) - 0.5
    full, local = (
        solve_reach_avoid(
            g,
            SimpleMotion.pursuit(1.0, 1.0),
            target,
            avoid,
            horizon=20.0,
            scheme=scheme,
            record_tstar=True,
            tol=0,
            local=local,
        )
        for local in (False, True)
    )
    assert_local_matches(full, local, g.spacing[0])


def test_a_local_solve_without_a_front_updates_nothing_and_agrees():
    """A target off the grid leaves no zero level to follow: the set stays
    empty on the full grid too, and the local solve does no work."""
    g = plane()
    x, y = g.mesh()
    full, local = (
        solve_reach_avoid(g, runner(), np.hypot(x - 50, y) - 1, horizon=1.0, local=local) for local in (False, True)
    )
    assert not full.reach_avoid_set.any() and not local.reach_avoid_set.any()
    assert local.node_updates == 0 < full.node_updates
