"""A walker's way to its goal: the direction toward the point a few metres
along the shortest path, traced only as far as that point."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
import shapely
from shapely.geometry import Point, box

from bearcat.agents.navigation import LOOK_AHEAD, Navigator, navigator
from bearcat.maps import Map
from bearcat.solvers.marching.descent import aim_ahead, descend


def walled_map() -> Map:
    return Map(name="walled", area=box(0, 0, 40, 30), origin=(37.8719, -122.2585), obstacles=(box(18, 0, 22, 22),))


def aim_along_the_whole_path(nav: Navigator, goal, position) -> np.ndarray:
    """The direction toward the point LOOK_AHEAD along the whole descent: what ``toward`` must give."""
    phi, seeds = nav._field(Point(goal) if isinstance(goal, tuple) else goal)
    path = descend(nav.grid, phi, np.asarray(position, float), seeds=seeds).points
    along = np.cumsum(np.r_[0.0, np.hypot(*np.diff(path, axis=0).T)])
    d = path[min(int(np.searchsorted(along, LOOK_AHEAD)), len(path) - 1)] - position
    return d / math.hypot(*d)


@pytest.mark.parametrize("spacing", [0.2, 0.5, 2.0])
@pytest.mark.parametrize("goal", [(35.0, 5.0), box(34, 2, 38, 8)])
@pytest.mark.parametrize("first", [None, 1])
def test_the_direction_is_that_of_the_whole_path(spacing, goal, first):
    """Also when the steps traced first (``_ahead``) fall short of the look-ahead."""
    nav = Navigator(walled_map(), spacing)
    nav._ahead = first or nav._ahead
    for position in [(5.0, 5.0), (17.5, 23.0), (25.0, 25.5), (30.0, 12.0)]:
        p = np.array(position)
        np.testing.assert_array_equal(nav.toward(goal, p), aim_along_the_whole_path(nav, goal, p))


def test_it_goes_round_the_wall_and_stops_inside_the_goal():
    nav = Navigator(walled_map(), 0.5)
    goal = box(34, 2, 38, 8)
    d = nav.toward(goal, np.array([5.0, 5.0]))
    assert d[1] > 0.5  # north first, towards the gap above the wall
    assert nav.toward(goal, np.array([36.0, 5.0])) is None
    assert nav.toward(goal, np.array([34.0, 5.0])) is None  # its edge covers
    assert nav.toward((35.0, 5.0), (35.0, 5.0)) is None
    assert shapely.is_prepared(goal)  # asked for ten times a second: prepared once


def test_the_aim_is_none_inside_a_wall_and_the_start_itself_on_the_goal():
    nav = Navigator(walled_map(), 0.5)
    phi, seeds = nav._field(box(34, 2, 38, 8))
    assert aim_ahead(nav.grid, phi, seeds, np.array([20.0, 10.0]), nav._ahead, LOOK_AHEAD) is None
    aim, points = aim_ahead(nav.grid, phi, seeds, np.array([36.0, 5.0]), nav._ahead, LOOK_AHEAD)
    assert points == 1 and np.array_equal(aim, [36.0, 5.0])


def test_games_on_one_map_share_its_navigator_while_the_map_lives():
    import gc
    import weakref

    game_map = walled_map()
    shared = navigator(game_map)
    shared.toward((35.0, 5.0), np.array([5.0, 5.0]))
    assert navigator(game_map) is shared and len(shared._fields) == 1
    assert navigator(walled_map()) is not shared
    gone = weakref.ref(shared)
    del game_map, shared
    gc.collect()
    assert gone() is None


WALKED = """
import json
import numpy as np
from shapely.geometry import box
from bearcat.maps import load_map
from bearcat.agents.navigation import Navigator, navigator
from bearcat.solvers.marching import descent

descent.compile_kernels()  # before any game, as the launcher's child does
counts = lambda: len(descent._aim.signatures)  # what it calls is compiled into it
warmed = counts()
moved = 0
for game_map, goal in ((load_map("campus-200"), (120.0, 60.0)), (load_map("field-50"), box(20, 40, 30, 48))):
    nav = navigator(game_map)
    for x in np.linspace(*game_map.bounds[0::2], 9):
        for y in np.linspace(*game_map.bounds[1::2], 9):
            moved += nav.toward(goal, np.array([x, y])) is not None
short = Navigator(load_map("field-50"))
short._ahead = 1  # a trace cut short of the look-ahead, traced again to the end
moved += short.toward((25.0, 45.0), np.array([5.0, 5.0])) is not None
print(json.dumps({"warmed": warmed, "after": counts(), "moved": moved}))
"""


def test_the_kernel_compiled_on_a_blank_grid_serves_every_walker():
    """After ``descent.compile_kernels`` (on a three-node grid, as ``bearcat
    run`` does while it solves) no walker on a real map compiles a kernel
    again, so none stands still at the start of its first game. A process
    of its own, so no other test's calls count."""
    done = subprocess.run([sys.executable, "-c", WALKED], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout.strip().splitlines()[-1])
    assert found["moved"] > 100, found
    assert found["warmed"] == found["after"] == 1, found
