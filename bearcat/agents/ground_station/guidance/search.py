"""Capture-the-flag guidance under limited visibility (thesis 6.2)."""

from __future__ import annotations

import msgspec
import numpy as np

from bearcat.agents.ground_station.guidance.ctf import CtfAdvisor
from bearcat.agents.ground_station.guidance.method import Advice, GuidanceView
from bearcat.agents.ground_station.guidance.outlines import mask_rings, on_the_wire
from bearcat.bus.messages import GameState
from bearcat.solvers.errors import InputError


class SearchAdvisor:
    """The CTF answer from what the agent's side knows; and for the side that
    flies the UAV, where the unseen defender may be (P_D, from its tasker)
    and the answer against the worst of those places: the value is the
    largest over P_D, so "go" means the attacker wins wherever the defender
    is, seen or not (``worst_case``). P_D grows with the time since the
    defender's last sighting was taken, so a stale sighting counts for what
    it is worth; with robust guidance the answer also holds wherever the
    attacker may be since its own last fix."""

    kind = "search"

    def __init__(self, ctf: CtfAdvisor, tasker, side) -> None:
        self.ctf = ctf
        self.tasker = tasker
        self.side = frozenset(side)
        self._drawn: tuple[int, list] = (-1, [])
        self._worst: tuple[tuple, dict | None] = ((), None)

    def state(self, message: GameState) -> None:
        self.ctf.state(message)

    def warm_up(self) -> None:
        self.ctf.warm_up()

    def forget(self) -> None:
        self.ctf.forget()
        self._drawn = (-1, [])
        self._worst = ((), None)

    def plain(self, view: GuidanceView) -> Advice:
        """The CTF answer at the fixes, and P_D with the answer against its worst."""
        return self._searching(view, self.ctf.plain(view), robust=False)

    def worst_case(self, view: GuidanceView) -> Advice:
        """The robust CTF answer, and P_D with the answer against its worst wherever the attacker may be."""
        return self._searching(view, self.ctf.worst_case(view), robust=True)

    def calibrated(self, view: GuidanceView) -> Advice:
        """The calibrated CTF answer, and P_D with the answer against its worst."""
        return self._searching(view, self.ctf.calibrated(view), robust=False)

    def _searching(self, view: GuidanceView, advice: Advice, robust: bool) -> Advice:
        """``advice``, for an agent of the side that flies the UAVs with what they search for."""
        agent, fixes = view.agent, view.fixes
        if agent not in self.side:
            return advice
        fields: dict = {"possible": self._possible()}
        if self.ctf.attacker in fixes.latest:
            # The worst of P_D is looked for again when the attacker's set grows by half a cell.
            radius = self.ctf.coarse(self.ctf.radius(self.ctf.attacker, fixes, view.now)) if robust else None
            fields.update(self._against_the_worst(agent, fixes.latest[self.ctf.attacker][0], radius))
        return msgspec.structs.replace(advice, **fields)

    def _against_the_worst(self, agent: str, a: np.ndarray, radius: float | None) -> dict:
        key = (agent, a[0], a[1], radius, self.tasker.picture.updates, self.ctf.phase, self.ctf.solved)
        if self._worst[0] != key:
            answer = None
            try:
                values = None if radius is None else self._defender_values(a, radius)
            except InputError:
                values = None
            worst = self.tasker.worst_case(a, values)
            if worst is not None:
                radii = None if radius is None else (radius, 0.0)
                answer = self.ctf.answer_at(agent, a, np.asarray(worst), radii)
                answer = {k: answer[k] for k in ("heading", "value", "go") if k in answer}
                answer["worst_case"] = "value" in answer
            self._worst = (key, answer)
        return self._worst[1] or {}

    def _defender_values(self, a: np.ndarray, radius: float) -> np.ndarray:
        """Over defender positions, the value against the worst of where the attacker may be."""
        robust = self.ctf.robust
        return robust.region_values("defender", robust.cover("attacker", self.ctf.placeable(a), radius), self.ctf.phase)

    def _possible(self) -> list:
        """P_D's outlines, redrawn only when the tasker updated it (once a second)."""
        picture = self.tasker.picture
        if picture.updates != self._drawn[0]:
            self._drawn = (picture.updates, on_the_wire(self.ctf.map, mask_rings(self.tasker.grid, picture.possible)))
        return self._drawn[1]
