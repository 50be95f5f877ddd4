"""Open-loop reach-avoid guidance (thesis ch. 4) for one attacker against
many defenders."""

from __future__ import annotations

import numpy as np

from bearcat.agents.ground_station.guidance.fixes import Uncertainty, nearest_inside
from bearcat.agents.ground_station.guidance.method import Advice, GuidanceView
from bearcat.agents.ground_station.guidance.outlines import mask_rings, on_the_wire
from bearcat.bus.messages import GameState
from bearcat.maps import Map, rasterize
from bearcat.maps.geodesy import bearing
from bearcat.solvers.errors import InputError


class ReachAvoidAdvisor:
    """The attacker's phone shows its safe-reachable set for the current
    stage, the planned path through the remaining targets as a line, its
    first stretch as the heading, and go when a safe path exists; ``value``
    is the time to the last target along it. Solved on a grid of ``spacing``
    metres on each new fix of the attacker.

    Its worst-case form grows each defender's capture disk by the radius
    its last fix leaves it (``uncertainty``), so the safe set and go hold
    wherever the defenders may be; the defenders' positions are then taken
    afresh once a second as well, as their disks grow, and ``uncertain``
    says the plain answer would differ."""

    kind = "reach-avoid"

    def __init__(
        self,
        game_map: Map,
        *,
        attacker: str,
        defenders,
        targets,
        speeds: dict,
        capture_radius: float,
        spacing: float,
        uncertainty: Uncertainty | None = None,
    ) -> None:
        self.map = game_map
        self.attacker, self.defenders = attacker, tuple(defenders)
        raster = rasterize(game_map, spacing)
        self.grid = raster.grid
        self.free = raster.free
        # Fixes that land on a blocked node go to the nearest point a spacing inside the free space.
        self._inside = game_map.free_space.buffer(-spacing)
        self.masks = [raster.masks[name] for name in targets]
        self.speed = {agent: v * raster.speed for agent, v in speeds.items()}
        self.uncertainty = uncertainty or Uncertainty(dict(speeds))
        self.capture_radius = capture_radius
        self.stage = 0
        self._last: tuple[tuple, Advice] | None = None

    def state(self, message: GameState) -> None:
        self.stage = 0 if message.flag_holder is None else min(1, len(self.masks) - 1)

    def warm_up(self) -> None:
        """Nothing to load ahead: the solver's code is compiled at the first answer, which ``forget`` drops."""

    def forget(self) -> None:
        """Keep no answer (see ``GuidanceService.warm_up``)."""
        self._last = None

    def plain(self, view: GuidanceView) -> Advice:
        """The attacker's answer at the defenders as last reported (a defender's phone shows positions only)."""
        return self._advice(view, robust=False)

    def worst_case(self, view: GuidanceView) -> Advice:
        """The attacker's answer with each defender's capture disk grown by the radius its last fix leaves it."""
        return self._advice(view, robust=True)

    def _advice(self, view: GuidanceView, robust: bool) -> Advice:
        latest, now = view.fixes.latest, view.now
        if view.agent != self.attacker:
            return Advice()
        if any(a not in latest for a in (self.attacker, *self.defenders)):
            return Advice(note="waiting for every player's fixes")
        points = [latest[a][0] for a in (self.attacker, *self.defenders)]
        # A solve takes tens of milliseconds: redo it when the stage changes or
        # the attacker's own fix moves (once a fix period), taking the
        # defenders as last reported then; a defender's move shows at the
        # attacker's next fix. Robust answers are also redone each second.
        grown = [0.0] * len(self.defenders)
        key: tuple = (self.stage, points[0].tobytes(), robust)
        if robust:
            grown = [self._radius(latest[d], d, now) for d in self.defenders]
            key += (int(now),)
        if self._last is None or self._last[0] != key:
            self._last = (key, Advice.of(self._answer(points, grown)))
        return self._last[1]

    def _radius(self, held, defender: str, now: float) -> float:
        _, t, fix = held
        r = self.uncertainty.radius(defender, now - t, fix.accuracy)
        assert r is not None, f"the uncertainty knows the top speed of {defender}"
        return r

    def _answer(self, points, grown) -> dict:
        a, *others = (self._placeable(p) for p in points)
        try:
            solution = self._solve(a, others, grown)
            plain = self._solve(a, others, [0.0] * len(others)) if any(grown) else solution
        except InputError as exc:
            return {"game": "reach-avoid", "note": str(exc)[:200]}
        fields = {"game": "reach-avoid", "region_of": self.attacker, "go": solution.reached}
        fields["uncertain"] = plain.reached != solution.reached
        fields["region"] = on_the_wire(self.map, mask_rings(self.grid, solution.stages[0].safe))
        if solution.path is not None and len(solution.path.points) > 1:
            path = solution.path.points
            along = np.cumsum(np.r_[0.0, np.hypot(*np.diff(path, axis=0).T)])
            aim = path[min(int(np.searchsorted(along, 3.0 * max(self.grid.spacing))), len(path) - 1)]
            if np.hypot(*(aim - a)) > 1e-9:
                fields["heading"] = bearing(*(aim - a))
            fields["boundary"] = on_the_wire(self.map, [path], 0.25 * min(self.grid.spacing))
            fields["value"] = float(solution.value)
        return fields

    def _solve(self, a, others, grown):
        from bearcat.solvers.marching.openloop import Defender, solve_openloop

        defenders = [
            Defender(tuple(p), self.speed[d], self.capture_radius + r) for d, p, r in zip(self.defenders, others, grown)
        ]
        masks = self.masks[self.stage :]
        return solve_openloop(self.grid, tuple(a), [self.speed[self.attacker]] * len(masks), masks, defenders)

    def _placeable(self, p: np.ndarray) -> np.ndarray:
        p = np.clip(p, self.grid.lo, self.grid.hi)
        if self.free[self.grid.nearest_index(p)]:
            return p
        return nearest_inside(self._inside, p)
