"""A ground station whose sets are not cached may start on provisional
ones, solved on a coarser grid, and take up its own once another process
has solved them: the coarser grid is derived from the capture radius or
set by the scenario and refused where it cannot serve; the cache answers
"solved yet?" without solving; after the hand-over the guidance answers
exactly as a ground station started on the game's own sets; the solve
behind the game stores them and, stopped, leaves no process running."""

import os

import pytest

from bearcat.agents.ground_station.ctf_cache import cached, load_or_solve
from bearcat.maps import load_map
from bearcat.maps.ctf_rules import provisional_grid
from bearcat.netem.profiles import load_profile
from bearcat.runtime.solve_ahead import SolveBehind
from bearcat.scenarios.cast import build_cast
from bearcat.scenarios.schema import ScenarioError, parse_scenario
from bearcat.solvers.ctf.queries import CtfQueries
from tests.support.answers import answering
from tests.support.live_runs import wait_for
from tests.test_guidance import fixes_at

GAME = """
[scenario]
name = "provisional"
map = "field-50"
game = "ctf"
time_limit = 30.0

[rules]
capture_radius = {radius}
stages = "return"
grid = {grid}
{provisional}

[guidance]
method = "none"  # answers at the fixes themselves, compared exactly across the sets

[[agent]]
id = "attacker"
team = "attacker"
start = [25.0, 22.0]
speed = 3.0
behaviour = "fake-out"
aided = true

[[agent]]
id = "defender"
team = "defender"
start = [25.0, 34.0]
speed = 3.0
behaviour = "direct"
aided = true
"""


def scenario(grid=17, provisional=11, radius=5.0):
    line = "" if provisional is None else f"provisional_grid = {provisional}"
    return parse_scenario(GAME.format(grid=grid, provisional=line, radius=radius), source="provisional.toml")


def ground(game, provisional=True):
    return build_cast(game, load_profile("ideal"), 0, people=[], provisional=provisional)


@pytest.fixture
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("BEARCAT_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


def test_the_derived_provisional_grid_has_a_cell_per_radius_and_is_well_below_the_games():
    field = load_map("field-50")
    # 1.2 cells per 2.5 m radius over 50 m: 24 cells, 25 points, the fake-out's.
    assert provisional_grid(field, 45, 2.5) == 25
    assert provisional_grid(field, 45, 10.0) == 21  # never below 21 points
    assert provisional_grid(field, 35, 2.5) is None  # 25 of 35 saves too little
    assert provisional_grid(field, 45, 2.5, asked=0) is None
    assert provisional_grid(field, 45, 2.5, asked=31) == 31


@pytest.mark.parametrize(
    ("grid", "provisional", "radius", "why"),
    [
        (17, 17, 5.0, "rules.provisional_grid 17 is not below rules.grid"),
        (45, 15, 2.5, "too coarse to resolve capture \\(use 21\\)"),
    ],
)
def test_a_provisional_grid_that_cannot_serve_is_refused_naming_it(grid, provisional, radius, why):
    with pytest.raises(ScenarioError, match=why):
        build_cast(scenario(grid, provisional, radius), load_profile("ideal"), 0, people=[], ground=False)


def test_a_provisional_ground_station_answers_from_coarse_sets_then_exactly_as_on_its_own(private_cache):
    game = scenario()
    cast = ground(game)
    awaited = cast.awaited
    assert (awaited.provisional, awaited.game.grid_points, awaited.stages) == (11, 17, "return")
    assert cast.guidance.advisor.solved.geometry.grid.shape == (11, 11)
    advisor = answering(cast.guidance.advisor)
    assert cached(awaited.game, awaited.stages) is None
    fixes = fixes_at(game.map, {"attacker": (20.0, 18.0), "defender": (27.0, 31.0)})
    before = {agent: advisor(agent, fixes, 1.0) for agent in ("attacker", "defender")}

    load_or_solve(awaited.game, awaited.stages)  # what the solve behind the game does
    found = cached(awaited.game, awaited.stages)
    assert found is not None and found.sources == {"return": "cache"}
    cast.adopt(CtfQueries(found.solution))

    own = ground(game)  # started once the game's own sets are in the cache
    assert own.awaited is None and own.guidance.advisor.solved.geometry.grid.shape == (17, 17)
    for agent in ("attacker", "defender"):
        after = advisor(agent, fixes, 1.0)  # the same fixes: what was kept of the old sets is gone
        assert after == answering(own.guidance.advisor)(agent, fixes, 1.0)
        assert after["value"] != before[agent]["value"]


def test_the_solve_behind_a_game_stores_its_sets_and_a_stopped_one_leaves_nothing_running(private_cache):
    awaited = ground(scenario()).awaited
    said = []
    behind = SolveBehind(awaited)
    assert behind.finish(said.append) and behind.done
    assert cached(awaited.game, awaited.stages) is not None
    assert not said or "17-point sets" in said[0]

    larger = ground(scenario(grid=45, provisional=21, radius=2.5)).awaited
    stopped = SolveBehind(larger)
    # Its first act: the lowest priority of an ordinary process, so the game's peers come first.
    assert wait_for(lambda: os.getpriority(os.PRIO_PROCESS, stopped.pid) == 19, 60), "the solve kept its priority"
    stopped.stop()
    assert stopped.done and not stopped.solved
    assert cached(larger.game, larger.stages) is None
