"""Capture-the-flag guidance (thesis 3.5): the attacker's phone shows the
defender's winning region R_D(x_a), its optimal heading and go (the reported
state is an attacker win); the defender's shows R_A(x_d) and its heading.

For an agent with robust guidance the fixes are not taken as exact: each
player is anywhere in the disk its last fix allows (``solvers.ctf_robust``),
go and "winning" hold against all of it, the region is the opponent's
region against the worst of it, and ``uncertain`` says that the plain
answer at the fixes would have said otherwise.
"""

from __future__ import annotations

import numpy as np

from bearcat.agents.ground_station.guidance.fixes import LatestFixes, Uncertainty, nearest_inside
from bearcat.agents.ground_station.guidance.outlines import on_the_wire, polygon_rings
from bearcat.bus.messages import GameState
from bearcat.maps import Map
from bearcat.maps.geodesy import bearing
from bearcat.solvers.ctf_queries import CtfQueries
from bearcat.solvers.ctf_robust import RobustCtf
from bearcat.solvers.errors import InputError

RADIUS_STEP = 0.25
"""Metres a set's radius is rounded up to, so an answer is reused while a fix ages by less."""


class CtfAdvisor:
    """The CTF fields of a phone's guidance, from the solved sets of one game."""

    def __init__(
        self,
        game_map: Map,
        solved: CtfQueries,
        *,
        attacker: str,
        defender: str,
        phase: str = "capture",
        robust=(),
        uncertainty: Uncertainty | None = None,
    ):
        self.map = game_map
        self.attacker, self.defender = attacker, defender
        self.phase = phase
        self.robust_for = frozenset(robust)
        rules = solved.solution.rules
        self.uncertainty = uncertainty or Uncertainty({attacker: rules.attacker_speed, defender: rules.defender_speed})
        self.adopt(solved)

    def adopt(self, solved: CtfQueries) -> None:
        """Answer from ``solved`` from now on: the same game on another grid
        (a ground station that started on provisional sets takes up its own).
        What was kept of the old sets' answers goes with them."""
        self.solved = solved
        self.robust = RobustCtf(solved) if self.robust_for else None
        spacing = min(solved.geometry.grid.spacing)
        # Fixes outside the free space go to its nearest point a whisker inside.
        self._inside = self.map.free_space.buffer(-0.05 * spacing)
        self._simplify = 0.25 * spacing
        self._region_step = 0.5 * spacing
        self._regions: dict[str, tuple[tuple, list]] = {}
        self._outlines: dict[str, tuple[tuple, list]] = {}
        self._last: dict[str, tuple[tuple, dict]] = {}

    def warm_up(self, starts) -> None:
        """Run the query kernels, then answer each side once with the
        players at ``starts`` (agent -> map point; robustly too where
        asked), and keep nothing. The first queries of a process load the
        compiled kernels from numba's cache (a third of a second) or, after
        a fresh clone, compile them (two seconds), and the first outline
        traced loads contourpy and shapely: see ``GuidanceService.warm_up``.
        It may run on another thread than the game's queries: those only
        read, and the robust region it may keep is the one the same fixes
        would give."""
        self.solved.warm_up()
        a, d = (np.asarray(starts[who], float) for who in (self.attacker, self.defender))
        radius = min(self.solved.geometry.grid.spacing)
        for agent in (self.attacker, self.defender):
            self.answer_at(agent, a, d)
            if agent in self.robust_for:
                self.answer_at(agent, a, d, (radius, radius))

    def state(self, message: GameState) -> None:
        self.phase = "capture" if message.flag_holder is None else "return"

    def __call__(self, agent: str, fixes: LatestFixes, now: float) -> dict:
        """The CTF fields of ``agent``'s guidance. They depend only on the two
        latest fixes and the phase (and, for robust guidance, the sets'
        radii, rounded up to ``RADIUS_STEP``), which change less often than
        guidance goes out, so the last answer per agent is kept."""
        latest = fixes.latest
        if self.attacker not in latest or self.defender not in latest:
            return {"game": "ctf", "note": "waiting for both players' fixes"}
        a, d = latest[self.attacker][0], latest[self.defender][0]
        radii = self.radii(fixes, now) if agent in self.robust_for else None
        key = (a[0], a[1], d[0], d[1], self.phase, radii)
        held = self._last.get(agent)
        if held is None or held[0] != key:
            held = self._last[agent] = (key, self.answer_at(agent, a, d, radii))
        return held[1]

    def radii(self, fixes: LatestFixes, now: float) -> tuple[float, float]:
        """The attacker's and the defender's uncertainty radii."""
        return self.radius(self.attacker, fixes, now), self.radius(self.defender, fixes, now)

    def radius(self, player: str, fixes: LatestFixes, now: float) -> float:
        """Where ``player`` may be by ``now``, from its latest fix, rounded up to ``RADIUS_STEP``."""
        _, t, fix = fixes.latest[player]
        r = self.uncertainty.radius(player, now - t, fix.accuracy)
        assert r is not None, f"the uncertainty knows the top speed of {player}"
        return float(np.ceil(r / RADIUS_STEP) * RADIUS_STEP)

    def answer_at(self, agent: str, a: np.ndarray, d: np.ndarray, radii=None) -> dict:
        """The CTF fields of ``agent``'s guidance with the attacker at ``a`` and
        the defender at ``d`` (map metres; moved out of buildings first);
        with ``radii``, robust against the disks of those radii round them."""
        try:
            a = self.placeable(a)
            d = self.placeable(d)
            if radii is not None:
                return self._robust_answer(agent, a, d, radii)
            report = self.solved.evaluate(a, d, self.phase)
        except InputError as exc:
            return {"game": "ctf", "note": str(exc)[:200]}
        if agent == self.attacker:
            side, region_of, heading, own = "defender", self.defender, report.attacker_heading, a
        else:
            side, region_of, heading, own = "attacker", self.attacker, report.defender_heading, d
        return {
            "game": "ctf",
            "heading": None if heading is None else bearing(*heading),
            "region": self._region(side, own),
            "region_of": region_of,
            "go": report.winner == "attacker" if agent == self.attacker else None,
            "value": float(report.value),
        }

    def _robust_answer(self, agent: str, a: np.ndarray, d: np.ndarray, radii) -> dict:
        robust = self.robust
        assert robust is not None  # made for the agents given robust guidance, as this one is
        covers = {"attacker": robust.cover("attacker", a, radii[0]), "defender": robust.cover("defender", d, radii[1])}
        side = "attacker" if agent == self.attacker else "defender"
        answer = robust.answer(side, covers["attacker"], covers["defender"], self.phase)
        own = (a, radii[0]) if side == "attacker" else (d, radii[1])
        return {
            "game": "ctf",
            "heading": None if answer.heading is None else bearing(*answer.heading),
            "region": self._robust_region(side, *own),
            "region_of": self.defender if side == "attacker" else self.attacker,
            "go": answer.wins if side == "attacker" else None,
            "value": float(answer.worst),
            "uncertain": answer.uncertain,
        }

    def coarse(self, radius: float) -> float:
        """``radius`` rounded up to half a cell: for what is redrawn only when a set grows by that much."""
        return float(np.ceil(radius / self._region_step) * self._region_step)

    def _region(self, side: str, where: np.ndarray) -> list:
        """The region of ``side`` against the other player at ``where``, as
        sent. It depends on that one position and the phase, while the
        answer it goes out in changes with either player's fix: it is kept
        until they change."""
        key = (side, where[0], where[1], self.phase)
        held = self._outlines.get(side)
        if held is None or held[0] != key:
            if side == "defender":
                values = self.solved.defender_region_values(where, self.phase)
            else:
                values = self.solved.attacker_region_values(where, self.phase)
            rings = on_the_wire(self.map, polygon_rings(self.solved.polygons(values, side)), self._simplify)
            held = self._outlines[side] = (key, rings)
        return held[1]

    def _robust_region(self, side: str, where: np.ndarray, radius: float) -> list:
        """The opponent's region against the worst of ``side``'s own set, as
        sent. It is there to be looked at, so it is redrawn only when the set's
        radius grows by half a cell (rounded up, so it errs towards caution)."""
        coarse = self.coarse(radius)
        key = (side, where[0], where[1], coarse, self.phase)
        held = self._regions.get(side)
        if held is None or held[0] != key:
            other = "defender" if side == "attacker" else "attacker"
            assert self.robust is not None  # made for the agents given robust guidance, as this one is
            values = self.robust.region_values(other, self.robust.cover(side, where, coarse), self.phase)
            rings = on_the_wire(self.map, polygon_rings(self.solved.polygons(values, other)), self._simplify)
            held = self._regions[side] = (key, rings)
        return held[1]

    def placeable(self, p: np.ndarray) -> np.ndarray:
        """``p``, or the nearest point of the free space if a fix put it in a building or off the map."""
        if self.solved.geometry.grid.contains(p) and not self.solved.blocked_at(p):
            return p
        return nearest_inside(self._inside, p)
