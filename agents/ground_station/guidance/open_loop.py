"""Open-loop reach-avoid guidance (thesis ch. 4) for one attacker against
many defenders."""

from __future__ import annotations

import numpy as np

from bearcat.agents.ground_station.guidance.fixes import LatestFixes, nearest_inside
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
    metres on each new fix of the attacker."""

    def __init__(
        self, game_map: Map, *, attacker: str, defenders, targets, speeds: dict, capture_radius: float, spacing: float
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
        self.capture_radius = capture_radius
        self.stage = 0
        self._last: tuple[tuple, dict] | None = None

    def state(self, message: GameState) -> None:
        self.stage = 0 if message.flag_holder is None else min(1, len(self.masks) - 1)

    def __call__(self, agent: str, fixes: LatestFixes, now: float) -> dict:
        latest = fixes.latest
        if agent != self.attacker:
            return {"game": "reach-avoid"}
        if any(a not in latest for a in (self.attacker, *self.defenders)):
            return {"game": "reach-avoid", "note": "waiting for every player's fixes"}
        points = [latest[a][0] for a in (self.attacker, *self.defenders)]
        # A solve takes tens of milliseconds: redo it when the stage changes or
        # the attacker's own fix moves (once a fix period), taking the
        # defenders as last reported then; a defender's move shows at the
        # attacker's next fix.
        key = (self.stage, points[0].tobytes())
        if self._last is None or self._last[0] != key:
            self._last = (key, self._answer(points))
        return self._last[1]

    def _answer(self, points) -> dict:
        from bearcat.solvers.openloop import Defender, solve_openloop

        a, *others = (self._placeable(p) for p in points)
        defenders = [Defender(tuple(p), self.speed[d], self.capture_radius) for d, p in zip(self.defenders, others)]
        masks = self.masks[self.stage :]
        try:
            solution = solve_openloop(self.grid, tuple(a), [self.speed[self.attacker]] * len(masks), masks, defenders)
        except InputError as exc:
            return {"game": "reach-avoid", "note": str(exc)[:200]}
        fields = {"game": "reach-avoid", "region_of": self.attacker, "go": solution.reached}
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

    def _placeable(self, p: np.ndarray) -> np.ndarray:
        p = np.clip(p, self.grid.lo, self.grid.hi)
        if self.free[self.grid.nearest_index(p)]:
            return p
        return nearest_inside(self._inside, p)
