"""Robust capture-the-flag answers (solvers/ctf/robust.py) against the
plain queries they are built on: the worst case never misses a state the
sets allow, a set of one point gives the plain answer, larger sets are
never better, the bound is tight to a fraction of a cell, and the robust
heading is never worse in the worst case than the plain one.

Fixes and true positions are drawn by hypothesis over two solved games: the
open ctf-10 arena (0.5 m cells) and campus-200, whose buildings clip the sets."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from bearcat.maps import load_map
from bearcat.maps.ctf import ctf_geometry
from bearcat.solvers.ctf.queries import CtfQueries, interpolate_2d
from bearcat.solvers.ctf.robust import RobustCtf
from bearcat.solvers.ctf.sets import EDGE_SLACK, Rules, solve_ctf
from bearcat.solvers.errors import InputError

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module", params=["ctf-10", "campus-200"])
def game(request):
    if request.param == "ctf-10":
        geometry, rules = ctf_geometry(load_map("ctf-10"), 21), Rules(capture_radius=0.8)
    else:
        geometry, rules = ctf_geometry(load_map("campus-200"), 25), Rules(capture_radius=12.0)
    queries = CtfQueries(solve_ctf(geometry, rules, "both", scheme="first"))
    return queries, RobustCtf(queries)


def allowed(queries, who: str, point) -> bool:
    """Where a player may be: on the grid, free, and for the defender outside the flag and the return strip."""
    g = queries.geometry
    field = g.blocked if who == "attacker" else np.minimum(np.minimum(g.flag, g.home), g.blocked)
    inside = g.grid.contains(point)
    return inside and interpolate_2d(field, np.array(g.grid.lo), np.array(g.grid.spacing), np.asarray(point)) >= (
        -EDGE_SLACK * min(g.grid.spacing)
    )


def a_place(data, queries, who: str) -> np.ndarray:
    lo, hi = np.array(queries.geometry.grid.lo), np.array(queries.geometry.grid.hi)
    unit = data.draw(st.tuples(st.floats(0, 1), st.floats(0, 1)), label=f"{who} fix")
    point = lo + np.array(unit) * (hi - lo)
    assume(allowed(queries, who, point))
    return point


def a_radius(data, queries, who: str) -> float:
    cells = data.draw(st.floats(0.0, 6.0), label=f"{who} radius in cells")
    return cells * min(queries.geometry.grid.spacing)


def two_fixes(data, queries):
    """The attacker's and the defender's fixes and their uncertainty radii."""
    a, d = a_place(data, queries, "attacker"), a_place(data, queries, "defender")
    return a, d, a_radius(data, queries, "attacker"), a_radius(data, queries, "defender")


def in_disk(data, centre, radius, label) -> np.ndarray:
    r = radius * math.sqrt(data.draw(st.floats(0, 1), label=f"{label} depth"))
    t = data.draw(st.floats(0, 2 * math.pi), label=f"{label} angle")
    return centre + r * np.array([math.cos(t), math.sin(t)])


@SETTINGS
@given(data=st.data())
def test_the_worst_cases_bound_the_value_at_every_truth_the_sets_allow(game, data):
    """So the robust go never fires when the truth inside the sets loses, and
    "winning" is never shown to a defender that is losing there."""
    queries, robust = game
    a, d, ra, rd = two_fixes(data, queries)
    phase = data.draw(st.sampled_from(["capture", "return"]))
    covers = robust.cover("attacker", a, ra), robust.cover("defender", d, rd)
    attacker, defender = robust.answer("attacker", *covers, phase), robust.answer("defender", *covers, phase)
    for k in range(5):
        truth_a, truth_d = in_disk(data, a, ra, f"attacker truth {k}"), in_disk(data, d, rd, f"defender truth {k}")
        if not (allowed(queries, "attacker", truth_a) and allowed(queries, "defender", truth_d)):
            continue
        value = queries.evaluate(truth_a, truth_d, phase).value
        assert attacker.worst >= value - 1e-6
        assert defender.worst <= value + 1e-6
        if value > 0:
            assert not attacker.wins, "a go with the truth in the sets losing"
        else:
            assert not defender.wins, "'winning' shown with the truth in the sets lost"


@SETTINGS
@given(data=st.data())
def test_robust_answers_are_the_plain_ones_at_zero_age_and_accuracy(game, data):
    queries, robust = game
    a, d = a_place(data, queries, "attacker"), a_place(data, queries, "defender")
    phase = data.draw(st.sampled_from(["capture", "return"]))
    covers = robust.cover("attacker", a, 0.0), robust.cover("defender", d, 0.0)
    plain = queries.evaluate(a, d, phase)
    for side in ("attacker", "defender"):
        answer = robust.answer(side, *covers, phase)
        assert answer.worst == pytest.approx(plain.value, abs=1e-6)
        assert answer.heading == getattr(plain, f"{side}_heading")
        assert not answer.uncertain


@SETTINGS
@given(data=st.data())
def test_a_larger_set_never_makes_the_worst_case_better(game, data):
    queries, robust = game
    a, d, ra, rd = two_fixes(data, queries)
    grow = data.draw(st.floats(1.0, 3.0), label="growth")
    small = robust.cover("attacker", a, ra), robust.cover("defender", d, rd)
    large = robust.cover("attacker", a, ra * grow), robust.cover("defender", d, rd * grow)
    assert robust.answer("attacker", *large).worst >= robust.answer("attacker", *small).worst - 1e-9
    assert robust.answer("defender", *large).worst <= robust.answer("defender", *small).worst + 1e-9


def test_the_worst_case_is_within_a_cell_of_the_sampled_one(game):
    """The covers err only on the disks' rims: the bound exceeds the largest
    value over thousands of sampled truths by less than a cell's worth."""
    queries, robust = game
    rng = np.random.default_rng(7)
    h = min(queries.geometry.grid.spacing)
    lo, hi = np.array(queries.geometry.grid.lo), np.array(queries.geometry.grid.hi)
    checked = 0
    while checked < 12:
        a, d = rng.uniform(lo, hi), rng.uniform(lo, hi)
        if not (allowed(queries, "attacker", a) and allowed(queries, "defender", d)):
            continue
        ra, rd = rng.uniform(0.5, 5.0, 2) * h
        worst = robust.answer("attacker", robust.cover("attacker", a, ra), robust.cover("defender", d, rd)).worst
        sampled = -np.inf
        for _ in range(2000):
            ta = a + ra * math.sqrt(rng.uniform()) * _unit(rng.uniform(0, 2 * math.pi))
            td = d + rd * math.sqrt(rng.uniform()) * _unit(rng.uniform(0, 2 * math.pi))
            if allowed(queries, "attacker", ta) and allowed(queries, "defender", td):
                sampled = max(sampled, queries.evaluate(ta, td, "capture").value)
        assert sampled - 1e-6 <= worst <= sampled + h
        checked += 1


@SETTINGS
@given(data=st.data())
def test_the_robust_heading_is_never_worse_in_the_worst_case_than_the_plain_one(game, data):
    queries, robust = game
    a, d, ra, rd = two_fixes(data, queries)
    assume(ra > 0)
    covers = robust.cover("attacker", a, ra), robust.cover("defender", d, rd)
    answer = robust.answer("defender", *covers, "capture")
    plain = answer.plain.defender_heading
    assume(answer.heading is not None and plain is not None)

    def after_a_step(heading) -> float:
        there = d + robust.step * np.asarray(heading)
        if not allowed(queries, "defender", there):
            return -math.inf
        return robust.answer("defender", covers[0], robust.cover("defender", there, 0.0), "capture").worst

    assert after_a_step(answer.heading) >= after_a_step(plain) - 1e-9


def test_bad_sets_are_refused_with_the_player_named(game):
    queries, robust = game
    free = np.argwhere(queries.geometry.free)[0]
    point = np.array(queries.geometry.grid.lo) + free * np.array(queries.geometry.grid.spacing)
    with pytest.raises(InputError, match="defender uncertainty radius"):
        robust.cover("defender", point, -1.0)
    with pytest.raises(InputError, match="attacker uncertainty radius"):
        robust.cover("attacker", point, math.nan)
    with pytest.raises(InputError, match=r"attacker at .* off the game's grid"):
        robust.cover("attacker", (1e6, 1e6), 1.0)


def _unit(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), math.sin(angle)])
