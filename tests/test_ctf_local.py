"""The local (narrow-band) solve of capture-the-flag games against the full
grid: flag return, flag capture and the two-stage game on an open field and
among buildings, set by set (``solvers.levelset.hji``, ``local``)."""

import pytest

from bearcat.maps import load_map
from bearcat.maps.ctf import ctf_geometry
from bearcat.solvers.ctf.sets import Rules, solve_ctf
from tests.support.local_band import assert_local_matches_full

GAMES = {
    "field-50": Rules(3.0, 3.0, capture_radius=2.5, capture_time=60.0, return_time=60.0),
    # Buildings, and a capture radius above the 8.3 m cells of a 25-point grid.
    "campus-200": Rules(3.0, 3.0, capture_radius=10.0, capture_time=60.0, return_time=60.0),
}


@pytest.mark.parametrize("map_name", GAMES)
def test_local_sets_and_time_to_win_match_the_full_grid(map_name):
    geometry = ctf_geometry(load_map(map_name), 25)
    full, local = (solve_ctf(geometry, GAMES[map_name], "all", local=local) for local in (False, True))
    cell = min(geometry.grid.spacing)
    for name, exact in full.sets.items():
        found = local.sets[name]
        assert found.steps == exact.steps and found.converged_at == exact.converged_at
        assert found.node_updates <= exact.node_updates == exact.steps * geometry.joint_grid().size
        assert_local_matches_full(
            exact.value, found.value, exact.time_to_win, found.time_to_win, exact.time / exact.steps, cell / 4
        )
