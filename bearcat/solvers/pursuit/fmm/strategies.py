"""The players of the pursuit game on a grid (thesis 5.2.2, 5.3.2): pursuers
that shrink the evader's safe-reachable area, pursuers that follow the
geodesic, and the evader that heads for the safe point it reaches last.
Strategies sharing one ``TravelTimes`` share its fronts and its last safe set."""

from __future__ import annotations

import math

import numpy as np

from bearcat.solvers.errors import InputError, non_negative, positive
from bearcat.solvers.pursuit.fmm.area_gradient import METHODS, AreaGradient, area_gradient
from bearcat.solvers.pursuit.fmm.headings import away, slide, toward
from bearcat.solvers.pursuit.fmm.safe_set import SafeSet, check_pursuer_speeds, march_safe_set
from bearcat.solvers.pursuit.fmm.travel_times import TravelTimes

__all__ = ["FarthestPointEvader", "FmmAreaPursuit", "GeodesicPursuit"]

# Beyond this turn a wall-deflected area heading lowers A at less than half
# the steepest rate. A pursuer pressed against a wall between it and the
# evader then chatters about the point where the wall's tangent is level in
# A and never captures (triangle-10, one pursuer: 2 of 150 trials with 85
# degrees, none with 60); the geodesic takes it round the obstacle instead.
_DESCENT_TURN = math.radians(60.0)


class _Game:
    """The travel times and the game's speeds and capture radius, checked
    once, shared by the strategies and the evader that need the safe set."""

    def __init__(self, travel_times: TravelTimes, evader_speed, pursuer_speeds, capture_radius) -> None:
        self.travel_times = travel_times
        self.evader_speed = positive(evader_speed, "evader speed")
        self.pursuer_speeds = check_pursuer_speeds(pursuer_speeds, None)
        self.capture_radius = non_negative(capture_radius, "capture radius")

    def _safe(self, e: np.ndarray, ps: np.ndarray) -> SafeSet:
        speeds = check_pursuer_speeds(self.pursuer_speeds, len(ps))
        return march_safe_set(self.travel_times, e, ps, self.evader_speed, speeds, self.capture_radius)


class FmmAreaPursuit(_Game):
    """Pursuers that shrink the area of ``S_e`` (thesis 5.2.2); the notes of
    ``area_gradient`` describe the two ``gradient`` methods. ``"boundary"``
    is the default: it follows the area where one-cell differences of a node
    count cannot (a boundary parallel to the grid does not move a node for a
    half-cell shift of the bisector), turns headings about five times less
    from step to step, and costs half as much. A pursuer without an active
    boundary, or whose area heading has no free direction within 60 degrees
    (none that lowers the area at half the steepest rate or more), takes the
    geodesic toward the evader, read from its own front, which is already
    computed."""

    def __init__(
        self,
        travel_times: TravelTimes,
        *,
        evader_speed: float = 1.0,
        pursuer_speeds=1.0,
        capture_radius: float = 0.5,
        gradient: str = "boundary",
    ):
        if gradient not in METHODS:
            raise InputError(f"gradient must be one of {', '.join(METHODS)}, got {gradient!r}")
        super().__init__(travel_times, evader_speed, pursuer_speeds, capture_radius)
        self.gradient = gradient

    def area_gradient(self, evader, pursuers) -> AreaGradient:
        """``dA/dx_p`` of every pursuer, by this strategy's method."""
        tt = self.travel_times
        return self._area_gradient(tt.check_point(evader, "evader"), tt.check_points(pursuers, "pursuers"))

    def headings(self, evader, pursuers) -> np.ndarray:
        """(N, 2) unit headings: ``-dA/dx_p`` for the pursuers with an active
        boundary, the geodesic toward the evader for the others."""
        tt = self.travel_times
        e = tt.check_point(evader, "evader")
        ps = tt.check_points(pursuers, "pursuers")
        ag = self._area_gradient(e, ps)
        out = np.zeros((len(ps), 2))
        for k, p in enumerate(ps):
            g = ag.gradient[k]
            norm = math.hypot(g[0], g[1])
            if ag.active[k] and norm > 0:
                d, ok = slide(tt, p, -g / norm, _DESCENT_TURN)
                if ok:
                    out[k] = d
                    continue
            out[k] = away(tt, tt.front(p), e)
        return out

    def _area_gradient(self, e: np.ndarray, ps: np.ndarray) -> AreaGradient:
        return area_gradient(
            self.travel_times, e, ps, self.evader_speed, self.pursuer_speeds, self.capture_radius, self.gradient
        )


class GeodesicPursuit:
    """Pure pursuit along the geodesic: one front from the evader, and each
    pursuer heads down its travel time (straight at the evader where the
    segment is the geodesic), so around obstacles rather than into them."""

    def __init__(self, travel_times: TravelTimes):
        self.travel_times = travel_times

    def headings(self, evader, pursuers) -> np.ndarray:
        tt = self.travel_times
        e = tt.check_point(evader, "evader")
        ps = tt.check_points(pursuers, "pursuers")
        front = tt.front(e)
        return np.array([toward(tt, front, p) for p in ps]).reshape(-1, 2)


class FarthestPointEvader(_Game):
    """The evader of thesis 5.3.2: it heads for ``y*``, the node of ``S_e`` it
    reaches last along safe paths (``argmax phi``), keeps that target until
    within half the capture radius of it (at least one spacing, so that point
    capture still re-targets), then picks the next. The heading is the first
    step of the geodesic to ``y*``, down the travel time from ``y*``: one
    front per target, reused while the target holds. With an empty ``S_e``
    it keeps heading for its old target, or stands still without one."""

    def __init__(
        self,
        travel_times: TravelTimes,
        *,
        evader_speed: float = 1.0,
        pursuer_speeds=1.0,
        capture_radius: float = 0.5,
    ):
        super().__init__(travel_times, evader_speed, pursuer_speeds, capture_radius)
        self.target: np.ndarray | None = None
        self.retargets = 0

    @property
    def arrival_radius(self) -> float:
        return max(self.capture_radius / 2, max(self.travel_times.spacing))

    def heading(self, evader, pursuers) -> np.ndarray:
        tt = self.travel_times
        e = tt.check_point(evader, "evader")
        if self.target is None or math.hypot(*(self.target - e)) <= self.arrival_radius:
            ps = tt.check_points(pursuers, "pursuers")
            safe = self._safe(e, ps)
            if safe.mask.any():
                far = int(np.argmax(np.where(safe.mask, safe.evader_time, -np.inf)))
                self.target = tt.grid.point(np.unravel_index(far, safe.mask.shape))
                self.retargets += 1
        if self.target is None:
            return np.zeros(2)
        return toward(tt, tt.front(self.target), e)
