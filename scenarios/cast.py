"""From a scenario to the agents that play it: people (walker, phone,
behaviour), the ground station's guidance service and the referee.

Both runtimes build their agents here, so a scenario means the same thing
in simulation and live. Every random stream is spawned from the run's seed
and the agent's name, so adding an agent does not change another's draws.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np
import shapely

from agents.ground_station.ctf_cache import CtfGame, default_rules, load_or_solve
from agents.ground_station.guidance import CtfAdvisor, GuidanceService, PursuitAdvisor, ReachAvoidAdvisor
from agents.ground_station.referee import Contest, Referee
from agents.human import behaviours
from agents.human.agent import HumanAgent
from agents.human.phone import Phone
from agents.human.walker import Walker
from agents.navigation import Navigator
from netem.profiles import Profile
from scenarios.schema import Scenario, ScenarioError
from solvers.ctf_guidance import Guidance as CtfGuidance

STREAMS = {"walker": 0, "phone": 1, "behaviour": 2}


def stream(seed: int, agent: str, purpose: str) -> np.random.Generator:
    """The generator of one agent's ``purpose`` in a run seeded ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(zlib.crc32(agent.encode()), STREAMS[purpose])))


@dataclass
class Cast:
    """Who plays a scenario: the ground station's ``referee`` and
    ``guidance`` (None in a cast of people only) and the ``people``."""

    people: dict[str, HumanAgent]
    referee: Referee | None = None
    guidance: object | None = None

    @property
    def agents(self) -> list:
        """In the order the runtimes start and tick them."""
        return [a for a in (self.referee, self.guidance) if a is not None] + list(self.people.values())


def cast(
    scenario: Scenario, profile: Profile, seed: int, *, people=None, ground: bool = True, ctf_progress=None,
    judge: str = "truth",
) -> Cast:
    """The agents of ``scenario``: the people named in ``people`` (default all)
    and, with ``ground``, the ground station's referee (judging on ``judge``:
    the simulation's truth, or the fixes when the players are real) and
    guidance service."""
    if scenario.game not in GAMES:
        raise ScenarioError(
            f"{scenario.source}: running {scenario.game} games is not supported yet; {' and '.join(GAMES)} are"
        )
    game = GAMES[scenario.game](scenario)
    chosen = scenario.ids if people is None else list(people)
    crowd = {a: game.person(scenario.agent(a), profile, seed) for a in chosen}
    if not ground:
        return Cast(crowd)
    if judge not in ("truth", "fixes"):
        raise ScenarioError(f"the referee judges on truth or fixes, not {judge!r}")
    return Cast(crowd, game.referee(on_truth=judge == "truth"), game.guidance(ctf_progress))


class _CtfGame:
    """Capture-the-flag as the scenario sets it up (thesis 3.1.1, 3.5)."""

    def __init__(self, scenario: Scenario) -> None:
        attackers, defenders = scenario.team("attacker"), scenario.team("defender")
        if len(attackers) != 1 or len(defenders) != 1:
            raise ScenarioError(f"{scenario.source}: capture-the-flag is 1 vs 1: one attacker and one defender")
        self.scenario = scenario
        self.attacker, self.defender = attackers[0], defenders[0]
        game_map, r = scenario.map, scenario.rules
        self.rules = default_rules(
            game_map, self.attacker.speed, self.defender.speed,
            capture_radius=r["capture_radius"], capture_time=r["capture_time"], return_time=r["return_time"],
        )  # fmt: skip
        self.flag = shapely.union_all([g.geometry for g in game_map.regions_with_role("flag")])
        self.home = shapely.union_all([g.geometry for g in game_map.regions_with_role("return")])
        self.flag_taken = r["stages"] == "return"
        self.phase = "return" if self.flag_taken else "capture"
        self.goals = {"capture": self.flag, "return": self.home}
        self._navigator = None

    def referee(self, on_truth: bool = True) -> Referee:
        contest = Contest(
            runners=(self.attacker.id,), chasers=(self.defender.id,), capture_radius=self.rules.capture_radius,
            time_limit=self.scenario.time_limit, teams=("attacker", "defender"),
            targets=(("home", self.home),) if self.flag_taken else (("flag", self.flag), ("home", self.home)),
            forbidden=(("flag", self.flag), ("return", self.home)), flag_taken=self.flag_taken,
        )  # fmt: skip
        return Referee(self.scenario.name, self.scenario.map, contest, on_truth=on_truth)

    def guidance(self, progress=None) -> GuidanceService:
        s = self.scenario
        solved = load_or_solve(CtfGame(s.map, s.rules["grid"], self.rules), s.rules["stages"], progress=progress)
        advisor = CtfAdvisor(
            s.map, CtfGuidance(solved.solution), attacker=self.attacker.id, defender=self.defender.id, phase=self.phase
        )
        return GuidanceService(
            s.name, s.map, s.ids, advisor=advisor, aided={a.id: a.aided for a in s.agents}, rate=s.guidance_rate
        )

    def person(self, spec, profile: Profile, seed: int) -> HumanAgent:
        if self._navigator is None:
            self._navigator = Navigator(self.scenario.map)
        attacking = spec.team == "attacker"
        opponent = self.defender if attacking else self.attacker
        forbidden = None if attacking else self.flag.union(self.home)
        situation = behaviours.Situation(spec.id, spec.team, (opponent.id,), self.goals[self.phase], forbidden, self._navigator)
        return _person(self.scenario, spec, profile, seed, situation, self.goals, self.phase, keep_out=forbidden)


class _PursuitGame:
    """Cooperative pursuit in a convex field, as in the experiments of thesis
    5.4: pursuers see the evader's safe-reachable set and their heading; the
    pursuers win by capture, the evader by lasting the time limit."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        free = scenario.map.free_space
        if not abs(free.area - free.convex_hull.area) <= 1e-9 * free.area:
            raise ScenarioError(f"{scenario.source}: pursuit guidance needs a convex field; map {scenario.map.name} is not")
        evaders = scenario.team("evader")
        if len(evaders) != 1:
            raise ScenarioError(f"{scenario.source}: a pursuit game has one evader")
        self.evader = evaders[0]
        self.pursuers = scenario.team("pursuer")
        self._navigator = None

    def referee(self, on_truth: bool = True) -> Referee:
        contest = Contest(
            runners=(self.evader.id,), chasers=tuple(p.id for p in self.pursuers),
            capture_radius=self.scenario.rules["capture_radius"], time_limit=self.scenario.time_limit,
            teams=("evader", "pursuer"), lasting_wins=True,
        )  # fmt: skip
        return Referee(self.scenario.name, self.scenario.map, contest, on_truth=on_truth)

    def guidance(self, progress=None) -> GuidanceService:
        s = self.scenario
        advisor = PursuitAdvisor(s.map, evader=self.evader.id, pursuers=[p.id for p in self.pursuers])
        return GuidanceService(
            s.name, s.map, s.ids, advisor=advisor, aided={a.id: a.aided for a in s.agents}, rate=s.guidance_rate
        )

    def person(self, spec, profile: Profile, seed: int) -> HumanAgent:
        if self._navigator is None:
            self._navigator = Navigator(self.scenario.map)
        opponents = tuple(p.id for p in self.pursuers) if spec.team == "evader" else (self.evader.id,)
        situation = behaviours.Situation(spec.id, spec.team, opponents, None, None, self._navigator)
        return _person(self.scenario, spec, profile, seed, situation, {}, "capture")


class _ReachAvoidGame:
    """The open-loop reach-avoid game of thesis ch. 4 played out: one attacker
    must reach the targets in turn; the defenders win by capture or when
    time runs out."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        attackers = scenario.team("attacker")
        if len(attackers) != 1:
            raise ScenarioError(f"{scenario.source}: a reach-avoid game has one attacker")
        self.attacker = attackers[0]
        self.defenders = scenario.team("defender")
        names = scenario.rules["targets"]
        self.targets = [(n, scenario.map.region(n).geometry) for n in names]
        self.goals = {"capture": self.targets[0][1], "return": self.targets[-1][1]}
        xmin, ymin, xmax, ymax = scenario.map.bounds
        self.radius = scenario.rules["capture_radius"] or 0.005 * max(xmax - xmin, ymax - ymin)
        self._navigator = None

    def referee(self, on_truth: bool = True) -> Referee:
        contest = Contest(
            runners=(self.attacker.id,), chasers=tuple(d.id for d in self.defenders), capture_radius=self.radius,
            time_limit=self.scenario.time_limit, teams=("attacker", "defender"), targets=tuple(self.targets),
        )  # fmt: skip
        return Referee(self.scenario.name, self.scenario.map, contest, on_truth=on_truth)

    def guidance(self, progress=None) -> GuidanceService:
        s = self.scenario
        xmin, ymin, xmax, ymax = s.map.bounds
        advisor = ReachAvoidAdvisor(
            s.map, attacker=self.attacker.id, defenders=[d.id for d in self.defenders],
            targets=s.rules["targets"], speeds={a.id: a.speed for a in s.agents}, capture_radius=self.radius,
            spacing=s.rules["spacing"] or max(xmax - xmin, ymax - ymin) / 200,
        )  # fmt: skip
        return GuidanceService(
            s.name, s.map, s.ids, advisor=advisor, aided={a.id: a.aided for a in s.agents}, rate=s.guidance_rate
        )

    def person(self, spec, profile: Profile, seed: int) -> HumanAgent:
        if self._navigator is None:
            self._navigator = Navigator(self.scenario.map)
        opponents = tuple(d.id for d in self.defenders) if spec.team == "attacker" else (self.attacker.id,)
        situation = behaviours.Situation(spec.id, spec.team, opponents, self.goals["capture"], None, self._navigator)
        return _person(self.scenario, spec, profile, seed, situation, self.goals, "capture")


GAMES = {"ctf": _CtfGame, "pursuit": _PursuitGame, "reach-avoid": _ReachAvoidGame}


def _person(scenario, spec, profile: Profile, seed: int, situation, goals, phase, keep_out=None) -> HumanAgent:
    walker = Walker(
        scenario.map, spec.start, speed=spec.speed, reaction=spec.reaction, heading_error=spec.heading_error,
        keep_out=keep_out, rng=stream(seed, spec.id, "walker"),
    )  # fmt: skip
    phone = Phone(
        spec.id, scenario.map, gps=profile.gps, compass=profile.compass, rng=stream(seed, spec.id, "phone"),
        fix_rate=spec.fix_rate,
    )  # fmt: skip
    behaviour = behaviours.make(spec.behaviour, spec.options, stream(seed, spec.id, "behaviour"))
    return HumanAgent(scenario.name, walker, phone, behaviour, situation, goals=goals, phase=phase)
