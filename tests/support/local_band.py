"""The agreement a local (narrow-band) solve owes the full grid's."""

import numpy as np
from scipy import ndimage

# Share of the compared nodes whose T* may differ by more than a step, all
# of them passed at a tangent (below): more would mean the exception hides
# a front that went astray. The local solves of the tests stay below 0.21 %
# (R_A on field-50); on the open square over 20 s, 0.07 % against the 1.2 %
# by which the full grid's own T* moves when its CFL number goes from 0.75
# to 0.6.
LATE_SHARE = 0.005


def assert_local_matches_full(full_value, local_value, full_tstar, local_tstar, dt, tangent):
    """The local set is the full grid's except within one cell of the full
    set's boundary, and T* is the full grid's within one time step ``dt``
    wherever both are finite, except at nodes the front passes at a
    tangent: those whose full value ends within ``tangent`` (a quarter of
    the value's rise over a cell, say) of zero. There the value hovers at
    zero for many steps, so the step in which it dips below is rounding,
    and the full grid's own T* moves by tens of steps there when its CFL
    number goes from 0.75 to 0.6."""
    inside = full_value <= 0
    boundary = (inside ^ ndimage.binary_erosion(inside, border_value=1)) | (
        ~inside ^ ndimage.binary_erosion(~inside, border_value=1)
    )
    near = ndimage.binary_dilation(boundary)
    wrong = ((local_value <= 0) != inside) & ~near
    assert not wrong.any(), f"{wrong.sum()} nodes beyond a cell of the boundary change side"
    both = np.isfinite(full_tstar) & np.isfinite(local_tstar)
    assert both.sum() > 1000  # the comparison sees a front that travelled
    passed_at_tangent = both & (np.abs(full_value) <= tangent)
    step = dt * (1 + 1e-6)
    apart = np.zeros(full_tstar.shape)
    apart[both] = np.abs(full_tstar[both] - local_tstar[both])
    late = apart > step
    astray = late & ~passed_at_tangent
    assert not astray.any(), f"T* is more than a step ({dt:.3f}) off at {astray.sum()} nodes not passed at a tangent"
    assert late.sum() <= LATE_SHARE * both.sum(), f"T* is more than a step off at {late.sum()} of {both.sum()} nodes"
