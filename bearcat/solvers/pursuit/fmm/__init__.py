"""Safe-reachable-area pursuit on a grid: non-convex domains, unequal speeds (thesis 5.2.2).

The evader's safe-reachable set ``S_e`` holds the nodes it reaches strictly
before any pursuer could capture it there, along a path of such nodes: the
modified fast marching method of thesis 4.1.3 and 4.1.5, run with
``solvers.marching.fmm``. Pursuers that bound part of ``S_e`` (an *active boundary*)
move to shrink its area ``A``; the others close in along the geodesic (pure
pursuit that goes around obstacles).

- ``travel_times``: ``TravelTimes``, the fronts from the points agents stand
  on over one speed map, cached by position, so a pursuer that did not
  move, the evader strategy and the pursuers asking about the same
  positions, or a fixed target reuse their travel times;
- ``rays``: where geodesics run straight and the direction each leaves its
  source in;
- ``safe_set``: ``S_e`` from those fronts;
- ``area_gradient``: ``dA/dx_p`` by recounting ``S_e`` (the thesis's) or by
  the first variation of its boundary (the default);
- ``headings``: along geodesics, slid clear of obstacles;
- ``strategies``: the area-minimising and geodesic pursuers and the
  farthest-point evader.
"""

from bearcat.solvers.pursuit.fmm.area_gradient import AreaGradient
from bearcat.solvers.pursuit.fmm.safe_set import SafeSet, safe_set
from bearcat.solvers.pursuit.fmm.strategies import FarthestPointEvader, FmmAreaPursuit, GeodesicPursuit
from bearcat.solvers.pursuit.fmm.travel_times import TravelTimes

__all__ = [
    "AreaGradient",
    "FarthestPointEvader",
    "FmmAreaPursuit",
    "GeodesicPursuit",
    "SafeSet",
    "TravelTimes",
    "safe_set",
]
