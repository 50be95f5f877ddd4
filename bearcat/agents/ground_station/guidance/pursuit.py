"""Cooperative pursuit guidance in a convex field (thesis 5.4)."""

from __future__ import annotations

import numpy as np
import shapely

from bearcat.agents.ground_station.guidance.method import Advice, GuidanceView
from bearcat.agents.ground_station.guidance.outlines import on_the_wire
from bearcat.bus.messages import GameState
from bearcat.maps import Map
from bearcat.maps.geodesy import bearing
from bearcat.solvers.errors import InputError


class PursuitAdvisor:
    """Each pursuer's phone shows the evader's safe-reachable set S_e (its
    Voronoi cell), the pursuer's own active boundary of it, and the heading
    that shrinks its area fastest (eq. 5.11; straight at the evader for a
    pursuer without a boundary); ``value`` is the area of S_e in square
    metres."""

    kind = "pursuit"

    def __init__(self, game_map: Map, *, evader: str, pursuers) -> None:
        from bearcat.solvers.pursuit.convex import area_minimising_headings, line_of_control, voronoi_cell

        self.map = game_map
        self.evader, self.pursuers = evader, tuple(pursuers)
        ring = np.asarray(game_map.area.exterior.coords)[:-1]
        self.domain = ring if game_map.area.exterior.is_ccw else ring[::-1]
        self._headings, self._cell, self._line = area_minimising_headings, voronoi_cell, line_of_control
        self._last: dict[str, tuple[tuple, Advice]] = {}

    def state(self, message: GameState) -> None:
        pass

    def warm_up(self) -> None:
        """Nothing to load ahead: the solver's code is compiled at the first answer, which ``forget`` drops."""

    def forget(self) -> None:
        """Keep no answer (see ``GuidanceService.warm_up``)."""
        self._last = {}

    def plain(self, view: GuidanceView) -> Advice:
        """A pursuer's answer at the positions as reported (the evader's phone shows positions only)."""
        agent, latest = view.agent, view.fixes.latest
        if agent not in self.pursuers or any(a not in latest for a in (self.evader, *self.pursuers)):
            return Advice(note="waiting for every player's fixes")
        e = latest[self.evader][0]
        ps = np.array([latest[p][0] for p in self.pursuers])
        key = (tuple(e), ps.tobytes())
        held = self._last.get(agent)
        if held is None or held[0] != key:
            held = self._last[agent] = (key, Advice.of(self._answer(agent, e, ps)))
        return held[1]

    def _answer(self, agent: str, e: np.ndarray, ps: np.ndarray) -> dict:
        k = self.pursuers.index(agent)
        try:
            heading = self._headings(self.domain, e, ps)[k]
            cell = self._cell(self.domain, e, ps)
            line = self._line(self.domain, e, ps, k)
        except InputError as exc:
            return {"game": "pursuit", "note": str(exc)[:200]}
        area = shapely.Polygon(cell).area if len(cell) >= 3 else 0.0
        fields = {"game": "pursuit", "region_of": self.evader, "value": float(area)}
        if np.any(heading):
            fields["heading"] = bearing(*heading)
        if len(cell) >= 3:
            fields["region"] = on_the_wire(self.map, [np.vstack([cell, cell[:1]])])
        if len(line):
            fields["boundary"] = on_the_wire(self.map, [line])
        return fields
