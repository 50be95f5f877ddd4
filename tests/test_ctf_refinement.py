"""Grid refinement of the flag-return set: from 35^4 to 45^4 nodes the
boundary of R_A must move by less than a cell (thesis 3.4 computed on 45^4).
A scheme whose set still drifts with the grid at this resolution would make
every slice the phones show depend on the grid rather than the game."""

import numpy as np
import pytest
from scipy import ndimage
from scipy.interpolate import RegularGridInterpolator

from bearcat.maps import load_map
from bearcat.maps.ctf import ctf_geometry
from bearcat.solvers.ctf.sets import Rules, solve_ctf

RULES = Rules(attacker_speed=1.0, defender_speed=1.0, capture_radius=0.5, capture_time=6.0, return_time=6.0)


def flag_return(n):
    geometry = ctf_geometry(load_map("ctf-10"), n)
    solution = solve_ctf(geometry, RULES, "return")
    return geometry, solution.sets["return"].value


@pytest.mark.slow
def test_the_flag_return_boundary_moves_less_than_a_cell_from_35_to_45_points():
    """On the full grid; the local band's sets are the full grid's
    (``test_ctf_local``), so they refine alike."""
    coarse_geometry, coarse = flag_return(35)
    fine_geometry, fine = flag_return(45)
    axes = coarse_geometry.grid.axes() * 2
    # The coarse value at the fine nodes; float64 so the comparison is of
    # the sets, not of rounding.
    at_fine = RegularGridInterpolator(axes, coarse.astype(np.float64))(
        np.stack(np.meshgrid(*(fine_geometry.grid.axes() * 2), indexing="ij"), axis=-1).reshape(-1, 4)
    ).reshape(fine.shape)
    fine_set, coarse_set = fine <= 0, at_fine <= 0
    assert 0.2 < fine_set.mean() < 0.95
    # Nodes of the fine grid more than one coarse cell from the fine set's
    # boundary must be classified alike on both grids.
    coarse_cell_in_fine_cells = (10 / 34) / (10 / 44)
    inside = ndimage.distance_transform_edt(fine_set)
    outside = ndimage.distance_transform_edt(~fine_set)
    far = np.where(fine_set, inside, outside) > coarse_cell_in_fine_cells
    moved = (fine_set != coarse_set) & far
    assert moved.sum() == 0, f"{moved.sum()} nodes farther than a cell from the boundary changed side"
    # And the sets differ somewhere near the boundary: the test sees the boundary.
    assert (fine_set != coarse_set).sum() > 0
