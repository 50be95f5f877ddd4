"""The 1 vs 1 capture-the-flag game of thesis chapter 3 on the HJI solver:
closed-loop play from inside each player's winning set, a defender that
plays badly, the stage switch of 3.3.2, W_A inside R_A and F_A, guidance
queries against the 4-D value, the disk cache, bad input, and a faster
defender never helping the attacker.

Coordinates are read off the maps and grids, never typed in, so the tests
hold wherever a map puts its flag and return strip."""

import json
import subprocess
import sys
import tracemalloc

import numpy as np
import pytest
import shapely
from scipy import ndimage

from bearcat.agents.ground_station import ctf_cache
from bearcat.agents.ground_station.ctf_cache import CtfGame, load_or_solve
from bearcat.maps import MapError, load_map
from bearcat.maps.ctf import ctf_geometry
from bearcat.solvers.ctf.playout import play
from bearcat.solvers.ctf.queries import CtfQueries, interpolate_2d
from bearcat.solvers.ctf.sets import CtfSolution, Rules, required_game_bytes, solve_ctf
from bearcat.solvers.errors import InputError

N = 21  # nodes per axis of the ctf-10 games: 0.5 m cells
RULES = Rules(attacker_speed=1.0, defender_speed=1.0, capture_radius=0.8, capture_time=12.0, return_time=12.0)
# The capture radius is 1.6 cells. The value is the deepest signed distance
# to a target the attacker can force its way to, and the return strip is
# 1 m wide: no attacker state lies more than half a metre (one cell) deep,
# except where the defender stands in the flag. Half a cell is as deep as
# this geometry allows "clearly inside W_A" to be; W_D reaches the capture
# radius, so one cell is clearly inside it.
ATTACKER_DEPTH = 0.5  # cells
DEFENDER_DEPTH = 1.0  # cells
PLAYS = 60  # states drawn per closed-loop check


def far_from_boundary(mask, cells):
    """Nodes more than ``cells`` node spacings from any node of the other class."""
    inside = ndimage.distance_transform_edt(mask)
    outside = ndimage.distance_transform_edt(~mask)
    return np.where(mask, inside, outside) > cells


def cell(geometry):
    return float(min(geometry.grid.spacing))


def inside(geometry, field, point):
    """``point`` lies in the region of the 2-D signed distance ``field``, as the referee sees it."""
    g = geometry.grid
    return interpolate_2d(field, np.asarray(g.lo), np.asarray(g.spacing), np.asarray(point, float)) <= 0


def defender_not_forfeited(geometry):
    """Joint nodes where the defender does not already stand in F or R, so
    the game is not over before it starts."""
    return (np.minimum(geometry.flag, geometry.home) > 0)[None, None, :, :]


def node_states(geometry, mask, count, seed=0):
    """Up to ``count`` joint states at nodes of ``mask``, drawn without
    replacement by a seeded generator: (attacker, defender, node index)."""
    nodes = np.argwhere(mask)
    assert len(nodes) > 0
    rng = np.random.default_rng(seed)
    x, y = geometry.grid.axes()
    picked = nodes[rng.choice(len(nodes), min(count, len(nodes)), replace=False)]
    return [((x[i], y[j]), (x[k], y[m]), (i, j, k, m)) for i, j, k, m in picked]


def flag_centre(game_map):
    (region,) = game_map.regions_with_role("flag")
    return np.array(region.geometry.centroid.coords[0])


# --- solved games, once per module ---


@pytest.fixture(scope="module")
def ctf10():
    return ctf_geometry(load_map("ctf-10"), N)


@pytest.fixture(scope="module", params=[False, True], ids=["full", "local"])
def weno_all(ctf10, request):
    """R_A, F_A and W_A on one grid with the accurate scheme, on the full
    grid and by the local solve (whose sets every test here must accept)."""
    return solve_ctf(ctf10, RULES, "all", scheme="weno5", local=request.param)


@pytest.fixture(scope="module")
def weno_game(weno_all):
    """The two-stage game (R_A then W_A) of the WENO5 solve, without F_A."""
    sets = {name: weno_all.sets[name] for name in ("return", "win")}
    return CtfQueries(CtfSolution(weno_all.geometry, weno_all.rules, sets))


@pytest.fixture(scope="module", params=[False, True], ids=["full", "local"])
def first_game(ctf10, request):
    """The two-stage game with the first-order scheme, for tests of logic."""
    return CtfQueries(solve_ctf(ctf10, RULES, "both", scheme="first", local=request.param))


@pytest.fixture(scope="module")
def capture_only(ctf10):
    return CtfQueries(solve_ctf(ctf10, RULES, "capture", scheme="first"))


@pytest.fixture(scope="module")
def campus():
    """campus-200 (buildings) on a coarse grid: enough for the refusals of
    states inside an obstacle."""
    game_map = load_map("campus-200")
    solution = solve_ctf(ctf_geometry(game_map, 17), Rules(), "return", scheme="first")
    return game_map, CtfQueries(solution)


# --- closed-loop play (thesis 3.4) ---


def attacker_states(queries, seed=0):
    geometry = queries.geometry
    value = queries.solution.sets["win"].value
    return node_states(
        geometry, (value < -ATTACKER_DEPTH * cell(geometry)) & defender_not_forfeited(geometry), PLAYS, seed
    )


def assert_the_attacker_wins_by_returning_the_flag(queries, states):
    geometry = queries.geometry
    lost, returned = [], 0
    for xa, xd, node in states:
        p = play(queries, xa, xd)
        if p.winner != "attacker":
            lost.append(f"{xa} vs {xd} (W_A value {queries.solution.sets['win'].value[node]:.3f}): {p.reason}")
            continue
        if p.reason == "returned the flag":
            returned += 1
            assert p.flag_time is not None and p.phases[-1] == "return"
            k = int(np.searchsorted(p.times, p.flag_time))
            assert inside(geometry, geometry.flag, p.attacker[k])
            assert inside(geometry, geometry.home, p.attacker[-1])
        else:
            # A losing defender may forfeit by walking into F or R.
            assert p.reason == "defender entered the flag or return region"
            assert inside(geometry, geometry.flag, p.defender[-1]) or inside(geometry, geometry.home, p.defender[-1])
    assert not lost, f"the attacker lost {len(lost)} of {len(states)} states inside W_A, e.g. {lost[:3]}"
    return returned


def test_closed_loop_first_order_strategies_win_for_the_attacker_from_deep_inside_W_A(first_game):
    states = attacker_states(first_game)
    assert len(states) >= 30
    returned = assert_the_attacker_wins_by_returning_the_flag(first_game, states)
    # Most wins go through the flag and home rather than by a forfeit.
    assert returned >= 0.8 * len(states)


def test_closed_loop_weno5_strategies_win_for_the_attacker_from_deep_inside_W_A(weno_game):
    states = attacker_states(weno_game)
    assert len(states) >= 30
    assert_the_attacker_wins_by_returning_the_flag(weno_game, states)


def test_an_attacker_holding_the_flag_with_the_defender_far_behind_brings_it_home(weno_game, ctf10):
    flag = flag_centre(load_map("ctf-10"))
    xa, xd = flag, flag + (-3.0, -2.5)  # the defender in the south-west, behind the attacker
    report = weno_game.evaluate(xa, xd, "return")
    assert report.value < -0.8 * ATTACKER_DEPTH * cell(ctf10)
    p = play(weno_game, xa, xd, phase="return")
    assert (p.winner, p.reason) == ("attacker", "reached the return region"), (p.reason, p.attacker[-1])


def test_closed_loop_weno5_strategies_win_for_the_defender_from_deep_inside_W_D(weno_game):
    value = weno_game.solution.sets["win"].value
    states = node_states(weno_game.geometry, value > DEFENDER_DEPTH * cell(weno_game.geometry), PLAYS, seed=1)
    assert len(states) >= 30
    reasons = {}
    for xa, xd, node in states:
        p = play(weno_game, xa, xd)
        assert p.winner == "defender", f"{xa} vs {xd} (W_A value {value[node]:.3f}): {p.reason}"
        reasons[p.reason] = reasons.get(p.reason, 0) + 1
    assert reasons.get("captured", 0) > 0


def test_closed_loop_first_order_strategies_win_for_the_defender_from_deep_inside_W_D(first_game):
    value = first_game.solution.sets["win"].value
    states = node_states(first_game.geometry, value > DEFENDER_DEPTH * cell(first_game.geometry), PLAYS, seed=2)
    assert len(states) >= 30
    for xa, xd, node in states:
        p = play(first_game, xa, xd)
        assert p.winner == "defender", f"{xa} vs {xd} (W_A value {value[node]:.3f}): {p.reason}"


def test_a_defender_that_stands_still_or_walks_away_loses_where_its_strategy_wins(first_game):
    # Thesis 3.5: with only one agent aided, the attacker's strategy
    # exploits a defender that does not play the game.
    geometry = first_game.geometry
    value = first_game.solution.sets["win"].value
    states = node_states(geometry, value > DEFENDER_DEPTH * cell(geometry), 40, seed=3)

    def stand_still(t, attacker, defender, phase):
        return None

    def walk_away(t, attacker, defender, phase):
        return defender - attacker

    held, exploited, walked = 0, 0, 0
    for xa, xd, _ in states:
        if play(first_game, xa, xd).winner != "defender":
            continue
        held += 1
        still = play(first_game, xa, xd, defender_policy=stand_still)
        if still.winner == "attacker":
            assert still.reason == "returned the flag" and still.flag_time is not None
            assert inside(geometry, geometry.home, still.attacker[-1])
            assert np.all(still.defender == still.defender[0])
            exploited += 1
        walked += play(first_game, xa, xd, defender_policy=walk_away).winner == "attacker"
    assert held >= 30
    assert exploited >= 0.5 * held
    assert walked >= 0.5 * held


def test_the_attacker_switches_from_capture_to_return_at_the_flag_and_never_back(first_game):
    geometry = first_game.geometry
    value = first_game.solution.sets["win"].value
    starts = attacker_states(first_game, seed=4)[:30]
    starts += node_states(geometry, (value > 0) & defender_not_forfeited(geometry), 30, seed=5)
    switched = 0
    for xa, xd, _ in starts:
        p = play(first_game, xa, xd)
        phases = list(p.phases)
        k = phases.index("return") if "return" in phases else len(phases)
        assert phases == ["capture"] * k + ["return"] * (len(phases) - k), phases
        if k == len(phases):
            assert p.flag_time is None
            continue
        switched += 1
        # The switch happens at the first referee check that finds the attacker in F.
        assert p.flag_time == pytest.approx(p.times[k])
        assert inside(geometry, geometry.flag, p.attacker[k])
        assert not any(inside(geometry, geometry.flag, a) for a in p.attacker[:k])
        assert p.duration - p.flag_time <= RULES.return_time + 1e-6
    assert switched >= 20


# --- the sets (thesis 3.3.1) ---


def test_the_two_stage_set_lies_inside_both_stage_sets_and_is_smaller_than_flag_capture(weno_all):
    r_a, f_a, w_a = (weno_all.sets[name].attacker_wins for name in ("return", "capture", "win"))
    away = far_from_boundary(w_a, 1.5)
    assert away.mean() > 0.5
    for name, stage in (("R_A", r_a), ("F_A", f_a)):
        outside = np.argwhere(w_a & ~stage & away)
        assert len(outside) == 0, f"{len(outside)} nodes of W_A outside {name}, e.g. {outside[:3].tolist()}"
    # Fig. 3.5a: the defender lets the attacker take the flag and blocks the return.
    given_up = f_a & ~w_a & far_from_boundary(f_a, 2) & far_from_boundary(w_a, 2)
    assert given_up.mean() > 0.05


def test_first_order_values_keep_the_two_stage_game_no_easier_than_flag_capture_node_by_node(
    first_game, capture_only, ctf10
):
    # W_A's target max(l_F, J_RA) lies above F_A's l_F everywhere, and a
    # monotone scheme keeps that order in every node.
    capture = capture_only.solution.sets["capture"].value
    win = first_game.solution.sets["win"].value
    assert (win >= capture - 1e-5).all()
    assert (win > capture + cell(ctf10)).mean() > 0.05


# --- guidance queries ---


def grid_nodes(geometry):
    n0, n1 = geometry.grid.shape
    return [(0, 0), (n0 - 1, n1 - 1), (n0 // 2, n1 // 2), (3, n1 - 4), (n0 - 3, 2), (n0 // 2, n1 // 4)]


@pytest.mark.parametrize("phase, name", [("capture", "win"), ("return", "return")])
def test_region_masks_are_the_sign_of_the_4d_value_at_grid_nodes(first_game, phase, name):
    value = first_game.solution.sets[name].value
    x, y = first_game.geometry.grid.axes()
    for i, j in grid_nodes(first_game.geometry):
        np.testing.assert_array_equal(first_game.defender_region((x[i], y[j]), phase), value[i, j] > 0)
        np.testing.assert_array_equal(first_game.attacker_region((x[i], y[j]), phase), value[:, :, i, j] <= 0)
        np.testing.assert_array_equal(first_game.defender_region_values((x[i], y[j]), phase), value[i, j])


def test_region_polygons_match_the_masks_in_area_and_place(first_game):
    geometry = first_game.geometry
    h = cell(geometry)
    x, y = geometry.grid.axes()
    checked = 0
    for i, j in grid_nodes(geometry):
        for phase in ("capture", "return"):
            for side, values in (
                ("defender", first_game.defender_region_values((x[i], y[j]), phase)),
                ("attacker", first_game.attacker_region_values((x[i], y[j]), phase)),
            ):
                mask = values > 0 if side == "defender" else values <= 0
                shape = first_game.polygons(values, side)
                count_area = mask.sum() * geometry.grid.cell_area
                assert abs(shape.area - count_area) <= h * shape.length + geometry.grid.cell_area
                # Nodes clearly on one side are on the same side of the outline.
                sure = far_from_boundary(mask, 1.5)
                for a, b in np.argwhere(sure)[::7]:
                    assert shape.covers(shapely.Point(x[a], y[b])) == mask[a, b], (phase, side, a, b)
                checked += mask.any() and (~mask).any()
    assert checked >= 10


def test_region_polygons_are_valid_geometries(first_game):
    geometry = first_game.geometry
    x, y = geometry.grid.axes()
    nodes = grid_nodes(geometry) + [geometry.grid.nearest_index(flag_centre(load_map("ctf-10")))]
    invalid = []
    for i, j in nodes:
        for phase in ("capture", "return"):
            for side, values in (
                ("defender", first_game.defender_region_values((x[i], y[j]), phase)),
                ("attacker", first_game.attacker_region_values((x[i], y[j]), phase)),
            ):
                shape = first_game.polygons(values, side)
                if not shape.is_valid:
                    invalid.append(f"{side} region at {(x[i], y[j])} ({phase}): {shapely.is_valid_reason(shape)}")
    assert not invalid, invalid


def test_region_outlines_are_traced_as_contourpys_own_generator_traces_them():
    """The generator the queries build directly gives what
    ``contourpy.contour_generator`` gives, point for point, also where
    values are not finite (masked, as it masks them)."""
    import contourpy

    from bearcat.solvers.ctf.queries import _filled_contours

    rng = np.random.default_rng(0)
    for trial in range(60):
        nx, ny = rng.integers(2, 40, 2)
        x, y = np.sort(rng.uniform(0, 100, nx)), np.sort(rng.uniform(0, 100, ny))
        z = rng.normal(size=(ny, nx)).cumsum(0).cumsum(1)
        z[rng.random(z.shape) < 0.05 * (trial % 3)] = [np.inf, np.nan][trial % 2]
        expected = contourpy.contour_generator(x, y, z, fill_type="OuterOffset")
        traced = _filled_contours(*np.meshgrid(x, y), z)
        for lower, upper in ((-5.0, 0.0), (0.0, 5.0)):
            (points, offsets), (want_points, want_offsets) = traced.filled(lower, upper), expected.filled(lower, upper)
            assert len(points) == len(want_points)
            for got, want in zip([*points, *offsets], [*want_points, *want_offsets]):
                np.testing.assert_array_equal(got, want)


def test_headings_are_unit_vectors(first_game, weno_game):
    for queries in (first_game, weno_game):
        for phase in ("capture", "return"):
            for xa, xd, _ in node_states(queries.geometry, np.ones(queries.solution.grid.shape, bool), 50, seed=6):
                # Off the nodes too: a third of a cell north-east.
                shift = cell(queries.geometry) / 3
                xa = np.minimum(np.add(xa, shift), queries.geometry.grid.hi)
                report = queries.evaluate(xa, xd, phase)
                for heading in (report.attacker_heading, report.defender_heading):
                    if heading is not None:
                        assert np.hypot(*heading) == pytest.approx(1.0, abs=1e-9)
                assert report.winner == ("attacker" if report.value <= 0 else "defender")


def test_states_off_the_grid_are_refused_naming_the_player(first_game):
    (xmin, ymin), (xmax, ymax) = first_game.geometry.grid.lo, first_game.geometry.grid.hi
    mid = ((xmin + xmax) / 2, (ymin + ymax) / 2)
    with pytest.raises(InputError, match=r"attacker .* off the game's grid"):
        first_game.evaluate((xmin - 0.5, mid[1]), mid)
    with pytest.raises(InputError, match=r"defender .* off the game's grid"):
        first_game.evaluate(mid, (mid[0], ymax + 0.5))
    with pytest.raises(InputError, match="defender"):
        first_game.evaluate(mid, (float("nan"), mid[1]))
    with pytest.raises(InputError, match="attacker"):
        first_game.defender_region((xmax + 1.0, mid[1]))
    with pytest.raises(InputError, match="defender"):
        play(first_game, mid, (xmin - 1.0, ymin))


def test_states_inside_a_building_are_refused_naming_the_player(campus):
    game_map, queries = campus
    building = max(game_map.obstacles, key=lambda o: o.area).centroid.coords[0]
    (home,) = game_map.regions_with_role("return")
    free = home.geometry.representative_point().coords[0]
    assert not queries.geometry.free[queries.geometry.grid.nearest_index(building)]
    queries.evaluate(free, (free[0] + 20.0, free[1]), "return")  # a free state is answered
    with pytest.raises(InputError, match=r"attacker .* inside an obstacle"):
        queries.evaluate(building, free, "return")
    with pytest.raises(InputError, match=r"defender .* inside an obstacle"):
        queries.evaluate(free, building, "return")
    with pytest.raises(InputError, match="defender"):
        queries.attacker_region(building, "return")
    with pytest.raises(InputError, match="attacker"):
        play(queries, building, free)


def test_the_return_phase_of_a_game_solved_for_flag_capture_only_is_refused(capture_only):
    geometry = capture_only.geometry
    (xmin, ymin), (xmax, _) = geometry.grid.lo, geometry.grid.hi
    a, d = (xmin + 1.0, ymin + 1.0), (xmax - 1.0, ymin + 1.0)
    assert capture_only.evaluate(a, d, "capture").value == pytest.approx(capture_only.evaluate(a, d).value)
    with pytest.raises(InputError, match="R_A"):
        capture_only.evaluate(a, d, "return")
    with pytest.raises(InputError, match="R_A"):
        capture_only.defender_region(a, "return")
    with pytest.raises(InputError, match="R_A"):
        play(capture_only, a, d, phase="return")
    with pytest.raises(InputError, match="phase"):
        capture_only.evaluate(a, d, "home")


# --- the disk cache ---


@pytest.fixture
def game():
    """ctf-10 at 17 points: 0.625 m cells, capture radius 1.6 cells."""
    return CtfGame(load_map("ctf-10"), 17, Rules(capture_radius=1.0), scheme="first")


def test_a_second_load_comes_from_the_cache_with_equal_values(game, tmp_path):
    first = load_or_solve(game, "both", root=tmp_path)
    assert first.sources == {"return": "solved", "win": "solved"}
    assert all(path.exists() and path.with_suffix(".json").exists() for path in first.paths.values())
    second = load_or_solve(game, "both", root=tmp_path)
    assert second.sources == {"return": "cache", "win": "cache"}
    for name in ("return", "win"):
        np.testing.assert_array_equal(second.solution.sets[name].value, first.solution.sets[name].value)
        assert second.solution.sets[name].converged == first.solution.sets[name].converged


def test_a_different_capture_radius_misses_the_cache(game, tmp_path):
    load_or_solve(game, "both", root=tmp_path)
    wider = CtfGame(game.map, game.grid_points, Rules(capture_radius=1.3), scheme=game.scheme)
    solved = load_or_solve(wider, "both", root=tmp_path)
    assert solved.sources == {"return": "solved", "win": "solved"}
    base = load_or_solve(game, "both", root=tmp_path)
    assert (solved.solution.sets["return"].attacker_wins <= base.solution.sets["return"].attacker_wins).all()
    assert (base.solution.sets["return"].attacker_wins & ~solved.solution.sets["return"].attacker_wins).any()


def test_sets_solved_by_other_solver_code_miss_the_cache(game, tmp_path, monkeypatch):
    """A pull that changes a solver between releases must not load the sets
    the old code stored: the key holds a hash of the solvers' source."""
    load_or_solve(game, "both", root=tmp_path)
    assert load_or_solve(game, "both", root=tmp_path).sources == {"return": "cache", "win": "cache"}
    before = _fingerprint_of(tmp_path / "before", SOLVER)
    after = _fingerprint_of(tmp_path / "after", SOLVER.replace("0.75", "0.9"))
    assert before != after and before.split(" source ")[0] == after.split(" source ")[0]
    monkeypatch.setattr(ctf_cache, "solver_fingerprint", lambda: after)
    assert load_or_solve(game, "both", root=tmp_path).sources == {"return": "solved", "win": "solved"}


SOLVER = '''"""A solver module as a reader sees it."""

# The Courant number of the scheme.
DEFAULT_CFL = 0.75


def step(u, dt):
    """One step of the scheme."""
    return u - DEFAULT_CFL * dt * u  # explicit Euler
'''


def _fingerprint_of(root, text: str) -> str:
    """The fingerprint of a solvers/ package under ``root`` holding one module, ``text``."""
    (root / "solvers").mkdir(parents=True)
    (root / "solvers" / "hji.py").write_text(text)
    return ctf_cache._fingerprint((root / "solvers",))


@pytest.mark.parametrize(
    "change, kept",
    [
        (("# The Courant number of the scheme.", "# The CFL number: see chapter 3.\n# Kept below one."), True),
        (("  # explicit Euler", ""), True),
        (('"""One step of the scheme."""', '"""One step of the scheme, forward in time,\n    of length dt."""'), True),
        (('"""A solver module as a reader sees it."""', '"""A solver module, documented anew."""'), True),
        (("DEFAULT_CFL = 0.75", "DEFAULT_CFL = 0.76"), False),
        (("u - DEFAULT_CFL", "u + DEFAULT_CFL"), False),
        (("return u - DEFAULT_CFL * dt * u", "return max(u - DEFAULT_CFL * dt * u, 0.0)"), False),
    ],
    ids=["comment", "trailing-comment", "docstring", "module-docstring", "number", "operator", "call"],
)
def test_the_solver_fingerprint_follows_the_code_not_its_comments_or_docstrings(tmp_path, change, kept):
    """A comment or docstring changed in a solver solves no game again; a
    number or a line of code changed does."""
    old, new = change
    assert old in SOLVER
    before = _fingerprint_of(tmp_path / "before", SOLVER)
    after = _fingerprint_of(tmp_path / "after", SOLVER.replace(old, new))
    assert (before == after) is kept


def test_the_code_is_parsed_once_per_change_and_a_damaged_note_of_it_is_parsed_again(tmp_path, monkeypatch):
    """Every process that opens the cache (each peer, each study worker)
    needs the fingerprint, and parsing the solvers takes most of a second:
    the result is kept under the hash of the files as written."""
    parsed = []
    code = ctf_cache._code
    monkeypatch.setattr(ctf_cache, "_code", lambda path: parsed.append(path) or code(path))
    monkeypatch.setenv("BEARCAT_CACHE_DIR", str(tmp_path / "cache"))
    first = _fingerprint_of(tmp_path / "a", SOLVER)
    assert len(parsed) == 1
    assert _fingerprint_of(tmp_path / "b", SOLVER) == first and len(parsed) == 1
    for note in (tmp_path / "cache" / "code").iterdir():
        note.write_text("not a digest")
    assert _fingerprint_of(tmp_path / "c", SOLVER) == first and len(parsed) == 2
    assert _fingerprint_of(tmp_path / "d", SOLVER.replace("explicit Euler", "forward Euler")) == first
    assert len(parsed) == 3


def test_the_flag_return_stage_is_shared_through_the_cache(game, tmp_path):
    both = load_or_solve(game, "both", root=tmp_path)
    alone = load_or_solve(game, "return", root=tmp_path)
    assert alone.sources == {"return": "cache"} and set(alone.solution.sets) == {"return"}
    np.testing.assert_array_equal(alone.solution.sets["return"].value, both.solution.sets["return"].value)
    # A longer capture stage changes W_A but not R_A.
    longer = CtfGame(game.map, game.grid_points, Rules(capture_radius=1.0, capture_time=15.0), scheme=game.scheme)
    assert load_or_solve(longer, "both", root=tmp_path).sources == {"return": "cache", "win": "solved"}


@pytest.mark.parametrize("damage", ["garbage", "truncated", "not finite"])
def test_a_damaged_cache_file_is_solved_again(game, tmp_path, damage, caplog):
    """A set written with NaN (by a solver that overflowed) counts as damaged
    too. A ground station polling for the sets (``cached``) takes a damaged
    one for one not there yet, quietly; the solve that replaces it says so."""
    first = load_or_solve(game, "both", root=tmp_path)
    path = first.paths["return"]
    if damage == "not finite":
        np.save(path, np.full_like(np.load(path), np.nan))
    else:
        path.write_bytes(b"\x93NUMPY garbage, not an array" * 4 if damage == "garbage" else path.read_bytes()[:300])
    with caplog.at_level("WARNING", logger=ctf_cache.__name__):
        assert [ctf_cache.cached(game, "both", root=tmp_path) for _ in range(3)] == [None] * 3
        assert not caplog.records
        again = load_or_solve(game, "both", root=tmp_path)
        assert [r.getMessage().count("unreadable") for r in caplog.records] == [1]
    assert again.sources == {"return": "solved", "win": "cache"}
    np.testing.assert_array_equal(again.solution.sets["return"].value, first.solution.sets["return"].value)
    assert load_or_solve(game, "both", root=tmp_path).sources == {"return": "cache", "win": "cache"}


def test_sets_a_process_loaded_are_read_again_once_a_file_changes(game, tmp_path, caplog):
    """A process keeps what it loaded, with its files' stamps: a load after a
    file was damaged in place (same size, same inode) sees it and solves."""
    load_or_solve(game, "both", root=tmp_path)
    kept = load_or_solve(game, "both", root=tmp_path)
    assert load_or_solve(game, "both", root=tmp_path) is kept and kept.sources == {"return": "cache", "win": "cache"}
    path = kept.paths["return"]
    np.save(path, np.full_like(np.load(path), np.nan))
    with caplog.at_level("WARNING", logger=ctf_cache.__name__):
        assert load_or_solve(game, "both", root=tmp_path).sources == {"return": "solved", "win": "cache"}
    assert [r.getMessage().count("unreadable") for r in caplog.records] == [1]


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # the speeds overflow float32, as meant
def test_the_solver_refuses_a_value_that_overflows_instead_of_converging_on_it():
    """Without the check a NaN value never changes between checks and counts as converged."""
    geometry = ctf_geometry(load_map("ctf-10"), 13)
    with pytest.raises(InputError, match="stopped being finite"):
        solve_ctf(geometry, Rules(attacker_speed=1e300, defender_speed=1e300), "return", scheme="first")


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # the speeds overflow float32, as meant
def test_a_solve_that_overflows_is_neither_cached_nor_used(tmp_path):
    """Speeds of 1e300 m/s overflow the HJI solver into NaN; the solver says so instead of
    reporting a converged set, and nothing is cached."""
    wild = CtfGame(load_map("ctf-10"), 13, Rules(attacker_speed=1e300, defender_speed=1e300), scheme="first")
    with pytest.raises(InputError, match=r"^the value function stopped being finite by t = .*an overflow"):
        load_or_solve(wild, "return", root=tmp_path)
    assert not list(tmp_path.rglob("*.npy"))


def test_an_empty_cache_file_is_solved_again(game, tmp_path):
    first = load_or_solve(game, "return", root=tmp_path)
    first.paths["return"].write_bytes(b"")
    assert load_or_solve(game, "return", root=tmp_path).sources == {"return": "solved"}


# --- bad input ---


def test_a_map_without_a_flag_is_refused():
    with pytest.raises(MapError, match="flag"):
        ctf_geometry(load_map("square-10"), 21)


@pytest.mark.parametrize("grid_points", [3, 8, 21.0])
def test_too_few_or_fractional_grid_points_are_refused(grid_points):
    with pytest.raises(MapError, match="grid"):
        ctf_geometry(load_map("ctf-10"), grid_points)


@pytest.mark.parametrize(
    "field, value",
    [
        ("attacker_speed", -1.0),
        ("defender_speed", 0.0),
        ("capture_time", float("inf")),
        ("return_time", float("nan")),
        ("capture_radius", -0.1),
    ],
)
def test_bad_rules_are_refused_naming_the_rule(field, value):
    with pytest.raises(InputError, match=field.replace("_", " ")):
        Rules(**{field: value})


def test_a_game_too_large_for_the_memory_limit_is_refused_before_allocating():
    geometry = ctf_geometry(load_map("ctf-10"), 61)  # 61^4 states: 55 MB a float32 array
    assert required_game_bytes(geometry, "both", scheme="weno5") > 300e6
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match=r"needs about \d+\.\d+ GB .* only 0\.00 GB"):
            solve_ctf(geometry, RULES, "both", memory_limit=1000)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 10e6


def test_unknown_stages_are_refused(ctf10):
    with pytest.raises(InputError, match="stages"):
        solve_ctf(ctf10, RULES, "flag")


# --- monotonicity in the rules ---


def test_a_faster_defender_never_grows_the_attackers_flag_return_set(ctf10):
    base = solve_ctf(ctf10, RULES, "return", scheme="first").sets["return"].attacker_wins
    faster_rules = Rules(1.0, 1.3, RULES.capture_radius, RULES.capture_time, RULES.return_time)
    faster = solve_ctf(ctf10, faster_rules, "return", scheme="first").sets["return"].attacker_wins
    assert (faster & ~base).sum() <= 0.001 * base.size
    assert (base & ~faster).sum() > 0.05 * base.size


SOLVE_ONCE = """
import json, sys
from pathlib import Path
from bearcat.agents.ground_station.ctf_cache import CtfGame, load_or_solve
from bearcat.maps import load_map
from bearcat.solvers.ctf.sets import Rules
rules = Rules(attacker_speed=1.0, defender_speed=1.0, capture_radius=0.8, capture_time=12.0, return_time=12.0)
solved = load_or_solve(CtfGame(load_map("ctf-10"), 21, rules, scheme="first"), "both", root=Path(sys.argv[1]))
print(json.dumps(solved.sources))
"""


def test_processes_after_the_same_sets_solve_them_once_and_the_others_load_them(tmp_path):
    solvers = [
        subprocess.Popen([sys.executable, "-c", SOLVE_ONCE, str(tmp_path)], stdout=subprocess.PIPE, text=True)
        for _ in range(3)
    ]
    sources = [json.loads(p.communicate(timeout=300)[0]) for p in solvers]
    assert sorted(s["return"] for s in sources) == ["cache", "cache", "solved"]
    assert sorted(s["win"] for s in sources) == ["cache", "cache", "solved"]


WARMED = """
import json, sys
import numpy as np
from bearcat.maps import load_map
from bearcat.maps.ctf import ctf_geometry
from bearcat.solvers.ctf import queries as ctf_queries
from bearcat.solvers.ctf.sets import CtfSolution, Rules, SetSolution, solve_ctf

ctf_queries.compile_kernels()  # before any real game, as the launcher's child does
kernels = ("interpolate_2d", "_value_and_gradient", "_finite_gradient", "_slice")
counts = lambda: [len(getattr(ctf_queries, k).signatures) for k in kernels]
warmed = counts()
geometry = ctf_geometry(load_map("ctf-10"), 21)
solved = solve_ctf(geometry, Rules(), "return", scheme="first")
queries = ctf_queries.CtfQueries(solved)
queries.warm_up()
# The same sets as a ground station loads them from the cache: read-only arrays.
frozen = {}
for name, s in solved.sets.items():
    value, tstar = s.value.copy(), s.time_to_win.copy()
    value.flags.writeable = tstar.flags.writeable = False
    frozen[name] = SetSolution(name, value, s.converged, s.converged_at, s.time, s.steps, tstar)
loaded = ctf_queries.CtfQueries(CtfSolution(geometry, solved.rules, frozen))
axes = [a for a in geometry.grid.axes()]
inside = 0
for x in axes[0][2:-2:3]:
    for y in axes[1][2:-2:3]:
        for u, v in ((x, y), (axes[0][-3], axes[1][2])):
            for q in (queries, loaded):
                try:
                    inside += q.evaluate((x, y), (u, v), "return").value <= 0
                    q.defender_region_values((x, y), "return")
                    q.attacker_region_values((u, v), "return")
                except ctf_queries.InputError:
                    pass
print(json.dumps({"warmed": warmed, "after": counts(), "inside": int(inside)}))
"""


def test_kernels_compiled_on_a_blank_game_serve_every_query_of_a_real_one():
    """After ``compile_kernels`` (on a blank game, as ``bearcat run`` does
    while it solves) no query of a real game compiles a kernel again: not
    its warm-up, not inside the set (T*'s gradient), not on sets just solved
    nor on sets loaded read-only as a ground station loads them. So the
    ground station finds every kernel in numba's cache and, having warmed
    up, never stalls in the game. A process of its own, so no other test's
    calls count."""
    done = subprocess.run([sys.executable, "-c", WARMED], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout.strip().splitlines()[-1])
    assert found["inside"] > 0, found
    assert all(n >= 1 for n in found["warmed"]) and found["after"] == found["warmed"], found
