"""The time to win by fast sweeping (``solvers.sweeping``) against closed
forms: the one-player eikonal it reduces to, and the open-square flag
return whose set geometry gives (``tests.support.flag_return``)."""

import math

import numba
import numpy as np
import pytest

from bearcat.solvers.sweeping import kernels
from bearcat.solvers.sweeping.game import solve_time_to_win, value_at
from tests.support.flag_return import STRIP, far_from_boundary, flag_return, flag_return_by_geometry, open_square

N = 21
RADIUS = 1.5


def game(n=N, speed_d=1.0):
    """The flag return of ``tests.support.flag_return`` with the players' speed maps."""
    g, target, avoid = open_square(n, RADIUS)
    return g, target, avoid, np.ones((n, n)), np.full((n, n), speed_d)


@pytest.fixture(scope="module")
def flag_return_swept():
    g, target, avoid, speed_a, speed_d = game()
    return g, solve_time_to_win(g.spacing, speed_a, speed_d, target, avoid, ceiling=60.0)


def test_the_swept_set_is_the_geometric_flag_return_away_from_its_edge_and_no_worse_than_marching(
    flag_return_swept,
):
    g, swept = flag_return_swept
    assert swept.converged
    exact = flag_return_by_geometry(g, RADIUS)
    found = swept.value <= 0
    far = far_from_boundary(exact, 1.5)
    assert far.sum() > 0.5 * g.size
    assert not ((found != exact) & far).any()
    _, marched = flag_return(N, "first", RADIUS)
    assert (found != exact).mean() <= (marched != exact).mean()


def test_the_time_to_win_is_finite_exactly_on_the_set_and_never_beats_running_straight_home(flag_return_swept):
    g, swept = flag_return_swept
    found = swept.value <= 0
    t = swept.time_to_win
    assert np.isfinite(t[found]).all() and np.isinf(t[~found]).all()
    xa = g.axes()[0][:, None, None, None]
    straight = np.broadcast_to(np.maximum(STRIP - xa, 0.0), g.shape)  # at speed 1, nobody in the way
    attacker_home = found & (xa < STRIP)
    attacker_home &= np.broadcast_to(g.axes()[2][None, None, :, None] < STRIP, g.shape)
    assert (t[attacker_home] >= straight[attacker_home] - 1e-9).all()


def test_without_a_defender_the_time_to_win_is_the_distance_home():
    """A defender that cannot move and never captures leaves the eikonal
    equation, whose first-order Godunov solution is exact for a straight
    edge: T* = (4 - x_a) / v_a."""
    g, target, _, speed_a, speed_d = game(speed_d=0.0)
    never = np.ones(g.shape)
    swept = solve_time_to_win(g.spacing, 2.0 * speed_a, speed_d, target, never, ceiling=60.0)
    xa = np.broadcast_to(g.axes()[0][:, None, None, None], g.shape)
    xd = np.broadcast_to(g.axes()[2][None, None, :, None], g.shape)
    playing = xd < STRIP  # the defender is not standing in the strip, which would forfeit at once
    np.testing.assert_allclose(swept.time_to_win[playing], np.maximum(STRIP - xa[playing], 0) / 2.0, atol=1e-9)


def test_a_horizon_cuts_the_set_to_the_states_won_within_it(flag_return_swept):
    _, swept = flag_return_swept
    for horizon in (1.0, 3.0, 30.0):
        within = value_at(swept, horizon, 1.0) <= 0
        np.testing.assert_array_equal(within, (swept.value <= 0) & (swept.time_to_win <= horizon))


@pytest.mark.parametrize("rhs", [0.0, 1.0])
def test_the_local_update_solves_the_discrete_game_equation(rhs):
    """The root each node takes: va A(u) - vd D(u) = rhs where that has a
    root, the largest u at which it is not above rhs otherwise."""
    rng = np.random.default_rng(5)
    for _ in range(2000):
        a0, a1, b0, b1 = rng.normal(0.0, 1.0, 4)
        if rng.random() < 0.2:
            a1 = math.inf
        if rng.random() < 0.2:
            b1 = -math.inf
        ia = rng.uniform(0.5, 2.0, 2)
        ib = rng.uniform(0.5, 2.0, 2)
        va, vd = rng.uniform(0.2, 2.0, 2)
        u = kernels.local_root(a0, a1, b0, b1, ia[0], ia[1], ib[0], ib[1], va, vd, rhs)

        def f(x, a0=a0, a1=a1, b0=b0, b1=b1, ia=ia, ib=ib, va=va, vd=vd):
            attacker = math.hypot(max(x - a0, 0) * ia[0], max(x - a1, 0) * ia[1])
            defender = math.hypot(max(b0 - x, 0) * ib[0], max(b1 - x, 0) * ib[1])
            return va * attacker - vd * defender - rhs

        assert f(u) <= 1e-9 and f(u + 1e-7) > 0


def test_sweeps_give_the_same_numbers_on_one_thread_as_on_several():
    g, target, avoid, speed_a, speed_d = game(n=13)
    threads = numba.get_num_threads()
    solved = []
    for n in sorted({1, threads}):
        numba.set_num_threads(n)
        try:
            solved.append(solve_time_to_win(g.spacing, speed_a, speed_d, target, avoid, ceiling=60.0))
        finally:
            numba.set_num_threads(threads)
    for other in solved[1:]:
        np.testing.assert_array_equal(other.value, solved[0].value)
        np.testing.assert_array_equal(other.time_to_win, solved[0].time_to_win)
