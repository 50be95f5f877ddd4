"""Capture-the-flag guidance (thesis 3.5): the attacker's phone shows the
defender's winning region R_D(x_a), its optimal heading and go (the reported
state is an attacker win); the defender's shows R_A(x_d) and its heading.

Its advisor answers in three forms, one for each built-in guidance method
(``methods``), each a way of treating the stale, noisy fixes:

- ``plain`` (method ``none``): the fixes are taken as exact, as in the thesis.
- ``worst_case`` (``worst-case``): each player is anywhere in the disk its last fix allows
  (``solvers.ctf.robust``), go and "winning" hold against all of it, the
  region is the opponent's region against the worst of it, and
  ``uncertain`` says that the plain answer at the fixes would have said
  otherwise.
- ``calibrated`` (``calibrated``): the players are where their trackers predict them now
  (``tracker``), the answers are the plain ones there, and what the
  prediction gets wrong is paid for as measured. The attacker's go holds
  when the value plus the calibrated margin for the reports' age is below
  zero (``calibration``); without a calibration the margin is the
  tracker's own, the ``1 - alpha`` quantile of the value over its belief,
  and the note says so. The defender's heading is the one whose step leaves
  a quantile of the value over samples of the belief best
  (``solvers.ctf.sampled``), and its value is that quantile.
  ``ablate`` (``guidance.ablate``) switches parts off for a study: with
  ``calibration`` the margin is the tracker's own, with ``belief`` the
  defender steers by the plain heading at the prediction.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bearcat.agents.ground_station.calibration import Calibration
from bearcat.agents.ground_station.guidance.fixes import LatestFixes, Uncertainty, nearest_inside
from bearcat.agents.ground_station.guidance.method import Advice, GuidanceView
from bearcat.agents.ground_station.guidance.outlines import on_the_wire, polygon_rings
from bearcat.agents.ground_station.tracker import Belief
from bearcat.bus.messages import GameState
from bearcat.maps import Map
from bearcat.maps.geodesy import bearing
from bearcat.solvers.ctf.queries import CtfQueries
from bearcat.solvers.ctf.robust import RobustCtf
from bearcat.solvers.ctf.sampled import SampledCtf
from bearcat.solvers.errors import InputError

RADIUS_STEP = 0.25
"""Metres a set's radius is rounded up to, so an answer is reused while a fix ages by less."""
SAMPLES_LOG2 = 6
"""2^6 = 64 joint samples of the belief: the quantiles calibrated guidance
acts on move by a few centimetres between draws of this size."""
REGION_SNAP = 0.25
"""Share of a cell a predicted position is rounded to before its region is
traced: a prediction moves at every answer, and the outline need not."""


@dataclass(frozen=True)
class Estimate:
    """Where calibrated guidance takes the players to be: the trackers'
    beliefs at ``t`` and the age of the older of their latest fixes."""

    t: float
    attacker: Belief
    defender: Belief
    age: float


@functools.cache
def draws() -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Fixed quasi-random draws, for each player a mode uniform and two
    standard normals: an unscrambled Sobol' sequence, shifted half a
    step off zero, the same for every answer (common random numbers).
    Drawn at the first answer: scipy.stats costs every peer a second to import."""
    from scipy.stats import norm, qmc

    points = qmc.Sobol(6, scramble=False).random_base2(SAMPLES_LOG2)
    points = (points + 0.5 / len(points)) % 1.0
    return (norm.ppf(points[:, 1:3]), points[:, 0]), (norm.ppf(points[:, 4:6]), points[:, 3])


class CtfAdvisor:
    """The CTF fields of a phone's guidance, from the solved sets of one
    game. ``calibration`` loads the game's calibration, the first time an
    attacker's calibrated go needs it (None: there is none)."""

    kind = "ctf"

    def __init__(
        self,
        game_map: Map,
        solved: CtfQueries,
        *,
        attacker: str,
        defender: str,
        phase: str = "capture",
        uncertainty: Uncertainty | None = None,
        calibration: Callable[[], Calibration | None] | None = None,
        alpha: float = 0.01,
        defender_quantile: float = 0.5,
        ablate: tuple[str, ...] = (),
    ):
        self.map = game_map
        self.attacker, self.defender = attacker, defender
        self.phase = phase
        rules = solved.solution.rules
        self.uncertainty = uncertainty or Uncertainty({attacker: rules.attacker_speed, defender: rules.defender_speed})
        self._load = calibration
        self._loaded: tuple[Calibration | None] | None = None
        self.alpha = alpha
        self.defender_quantile = defender_quantile
        self.ablate = frozenset(ablate)
        self.adopt(solved)

    def adopt(self, solved: CtfQueries) -> None:
        """Answer from ``solved`` from now on: the same game on another grid
        (a ground station that started on provisional sets takes up its own).
        What was kept of the old sets' answers goes with them."""
        self.solved = solved
        self._robust: RobustCtf | None = None
        self._sampled: SampledCtf | None = None
        spacing = min(solved.geometry.grid.spacing)
        # Fixes outside the free space go to its nearest point a whisker inside.
        self._inside = self.map.free_space.buffer(-0.05 * spacing)
        self._simplify = 0.25 * spacing
        self._region_step = 0.5 * spacing
        self.forget()

    def forget(self) -> None:
        """Keep no answer: what a warm-up answered is not what a game's first fix is answered from."""
        self._regions: dict[str, tuple[tuple, list]] = {}
        self._outlines: dict[str, tuple[tuple, list]] = {}
        self._last: dict[str, tuple[tuple, Advice]] = {}
        self._drawn: tuple[Belief, Belief, tuple[np.ndarray, np.ndarray]] | None = None

    def warm_up(self) -> None:
        """Run the query kernels of every phase once and keep nothing: the
        first queries of a process load them from numba's cache (a third of
        a second) or, after a fresh clone, compile them (two seconds); see
        ``GuidanceService.warm_up``. It may run on another thread than the
        game's queries: those only read."""
        self.solved.warm_up()

    @property
    def robust(self) -> RobustCtf:
        """The robust queries of worst-case answers, made at the first."""
        if self._robust is None:
            self._robust = RobustCtf(self.solved)
        return self._robust

    @property
    def sampled(self) -> SampledCtf:
        """The queries over a belief's samples of calibrated answers, made at the first."""
        if self._sampled is None:
            self._sampled = SampledCtf(self.solved)
        return self._sampled

    def state(self, message: GameState) -> None:
        self.phase = "capture" if message.flag_holder is None else "return"

    def plain(self, view: GuidanceView) -> Advice:
        """The answer at the latest fixes, taken as exact."""
        return self._at_fixes(view, robust=False)

    def worst_case(self, view: GuidanceView) -> Advice:
        """The answer that holds wherever the players may be since their latest fixes."""
        return self._at_fixes(view, robust=True)

    def calibrated(self, view: GuidanceView) -> Advice:
        """The answer where the trackers predict the players now (see the module's docstring)."""
        estimate = self.estimate(view.fixes, view.now)
        if estimate is None:
            return Advice(note="waiting for both players' fixes")
        return Advice.of(self.calibrated_answer(view.agent, estimate))

    def _at_fixes(self, view: GuidanceView, robust: bool) -> Advice:
        """The plain or robust answer for ``view``'s agent. It depends only
        on the two latest fixes and the phase (and, for robust guidance, the
        sets' radii, rounded up to ``RADIUS_STEP``), which change less often
        than guidance goes out, so the last answer per agent is kept."""
        agent, fixes, latest = view.agent, view.fixes, view.fixes.latest
        if self.attacker not in latest or self.defender not in latest:
            return Advice(note="waiting for both players' fixes")
        a, d = latest[self.attacker][0], latest[self.defender][0]
        radii = self.radii(fixes, view.now) if robust else None
        key = (a[0], a[1], d[0], d[1], self.phase, radii)
        held = self._last.get(agent)
        if held is None or held[0] != key:
            held = self._last[agent] = (key, Advice.of(self.answer_at(agent, a, d, radii)))
        return held[1]

    def estimate(self, fixes: LatestFixes, now: float) -> Estimate | None:
        """Where the trackers of ``fixes`` believe both players are at
        ``now``; None until both have a fix."""
        beliefs = fixes.beliefs(now)
        if self.attacker not in beliefs or self.defender not in beliefs:
            return None
        oldest = min(fixes.latest[self.attacker][1], fixes.latest[self.defender][1])
        return Estimate(now, beliefs[self.attacker], beliefs[self.defender], now - oldest)

    def estimated_value(self, estimate: Estimate) -> float:
        """The value calibrated guidance uses: at the players' predicted positions, placed in the free space."""
        a, d = self.placeable(estimate.attacker.position), self.placeable(estimate.defender.position)
        return float(self.solved.evaluate(a, d, self.phase).value)

    def calibrated_answer(self, agent: str, estimate: Estimate) -> dict:
        """The CTF fields of ``agent``'s calibrated guidance (see the module's docstring)."""
        sampled = self.sampled
        try:
            a = self.placeable(estimate.attacker.position)
            d = self.placeable(estimate.defender.position)
            report = self.solved.evaluate(a, d, self.phase)
        except InputError as exc:
            return {"game": "ctf", "note": str(exc)[:200]}
        if agent == self.attacker:
            margin, note = self._margin(estimate, float(report.value))
            return {
                "game": "ctf",
                "heading": None if report.attacker_heading is None else bearing(*report.attacker_heading),
                "region": self._region_near("defender", a),
                "region_of": self.defender,
                "go": margin is not None and report.value + margin < 0,
                "value": float(report.value),
                "margin": None if margin is None else round(margin, 3),
                "note": note,
            }
        if "belief" in self.ablate:
            heading, value = report.defender_heading, float(report.value)
        else:
            attackers, defenders = self._samples(estimate)
            answer = sampled.answer(
                "defender", attackers, defenders, self.defender_quantile, self.phase, (report.defender_heading,)
            )
            heading, value = answer.heading, answer.value
        return {
            "game": "ctf",
            "heading": None if heading is None else bearing(*heading),
            "region": self._region_near("attacker", d),
            "region_of": self.attacker,
            "go": None,
            "value": value,
        }

    def _samples(self, estimate: Estimate) -> tuple[np.ndarray, np.ndarray]:
        """The joint samples of ``estimate``'s beliefs (``draws()`` through
        each), drawn once for both players' answers at one moment."""
        held = self._drawn
        if held is None or held[0] is not estimate.attacker or held[1] is not estimate.defender:
            (za, ua), (zd, ud) = draws()
            samples = (estimate.attacker.draw(za, ua), estimate.defender.draw(zd, ud))
            held = self._drawn = (estimate.attacker, estimate.defender, samples)
        return held[2]

    def _margin(self, estimate: Estimate, value: float) -> tuple[float | None, str]:
        """The margin the attacker's go adds to ``value``, and what the phone is told of it."""
        calibration = self.calibration()
        if calibration is None:
            own = self.sampled.quantile(*self._samples(estimate), 1.0 - self.alpha, self.phase) - value
            if "calibration" in self.ablate:
                return own, "calibration switched off (guidance.ablate): the margin is the tracker's own"
            return own, "not calibrated yet: the margin is the tracker's own (bearcat calibrate)"
        margin = calibration.margin(self.phase, estimate.age)
        if margin is None:
            return None, f"no go on reports {estimate.age:.1f} s old: the calibration has too few games that old"
        return margin, ""

    def calibration(self) -> Calibration | None:
        """The game's calibration, loaded at the first go that takes it; None
        where there is none or ``guidance.ablate`` switches it off."""
        if "calibration" in self.ablate or self._load is None:
            return None
        if self._loaded is None:
            self._loaded = (self._load(),)
        return self._loaded[0]

    def _region_near(self, mover: str, where: np.ndarray) -> list:
        """The opponent's region against ``mover`` at ``where``, as sent,
        traced at ``where`` rounded to ``REGION_SNAP`` of a cell."""
        snap = REGION_SNAP * min(self.solved.geometry.grid.spacing)
        near = np.round(where / snap) * snap
        if not self.solved.geometry.grid.contains(near) or self.solved.blocked_at(near):
            near = where
        key = ("near", near[0], near[1], self.phase)
        held = self._regions.get(mover)
        if held is None or held[0] != key:
            if mover == "attacker":
                values, side = self.solved.defender_region_values(near, self.phase), "defender"
            else:
                values, side = self.solved.attacker_region_values(near, self.phase), "attacker"
            rings = on_the_wire(self.map, polygon_rings(self.solved.polygons(values, side)), self._simplify)
            held = self._regions[mover] = (key, rings)
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
            values = self.robust.region_values(other, self.robust.cover(side, where, coarse), self.phase)
            rings = on_the_wire(self.map, polygon_rings(self.solved.polygons(values, other)), self._simplify)
            held = self._regions[side] = (key, rings)
        return held[1]

    def placeable(self, p: np.ndarray) -> np.ndarray:
        """``p``, or the nearest point of the free space if a fix put it in a building or off the map."""
        if self.solved.geometry.grid.contains(p) and not self.solved.blocked_at(p):
            return p
        return nearest_inside(self._inside, p)
