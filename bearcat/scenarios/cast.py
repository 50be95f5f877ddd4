"""From a scenario to the agents that play it: people (walker, phone,
behaviour), the ground station's guidance service and the referee.

Both runtimes build their agents here, so a scenario means the same thing
in simulation and live. Every random stream is spawned from the run's seed
and the agent's name, so adding an agent does not change another's draws.
"""

from __future__ import annotations

import functools
import logging
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
import shapely

from bearcat.agents.ground_station.calibration import Calibration
from bearcat.agents.ground_station.calibration_store import calibrate_command, load_calibration
from bearcat.agents.ground_station.ctf_cache import CtfGame, load_or_solve, stored
from bearcat.agents.ground_station.guidance import (
    CtfAdvisor,
    GuidanceService,
    PursuitAdvisor,
    ReachAvoidAdvisor,
    SearchAdvisor,
)
from bearcat.agents.ground_station.guidance.fixes import Uncertainty
from bearcat.agents.ground_station.guidance.method import TRACKS
from bearcat.agents.ground_station.referee import Contest, Referee
from bearcat.agents.ground_station.sight import Sight
from bearcat.agents.ground_station.tasking import Uav
from bearcat.agents.ground_station.tracker import Motion, Trackers
from bearcat.agents.ground_station.uav_tasking import PERIOD, UavTasker
from bearcat.agents.guard import Guard
from bearcat.agents.human.agent import HumanAgent
from bearcat.agents.human.behaviour import Situation
from bearcat.agents.human.phone import Phone
from bearcat.agents.human.walker import Walker
from bearcat.agents.navigation import Navigator, navigator
from bearcat.agents.registry import Entry
from bearcat.agents.uav.agent import UavAgent
from bearcat.agents.uav.airframe import Airframe
from bearcat.agents.uav.autopilot import SimulatedAutopilot
from bearcat.maps.ctf_rules import default_rules, provisional_grid, unresolved_capture
from bearcat.netem.profiles import Profile
from bearcat.scenarios.game import Game
from bearcat.scenarios.schema import CtfRules, PursuitRules, ReachAvoidRules, Scenario, ScenarioError
from bearcat.solvers.ctf.queries import CtfQueries

log = logging.getLogger(__name__)
TASKER = "uav-tasking"  # the name the ground station's UAV tasking goes by in logs and streams
_UNCALIBRATED: set[tuple[str, str, float, tuple[str, ...]]] = set()
"""The scenarios, profiles and alphas this process has said it has no calibration of."""

STREAMS = {"walker": 0, "phone": 1, "behaviour": 2, "uav": 3, "tasking": 4, "guidance": 5}
_Rules = TypeVar("_Rules", CtfRules, ReachAvoidRules, PursuitRules)


def stream(seed: int, agent: str, purpose: str) -> np.random.Generator:
    """The generator of one agent's ``purpose`` in a run seeded ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(zlib.crc32(agent.encode()), STREAMS[purpose])))


@dataclass(frozen=True)
class AwaitedSets:
    """The sets a ground station answering from provisional ones waits for:
    ``game`` solved for ``stages``, until then answered from its
    ``provisional``-point sets."""

    game: CtfGame
    stages: str
    provisional: int


def awaited_sets(scenario: Scenario) -> AwaitedSets | None:
    """The sets a ground station of ``scenario`` started on provisional sets
    now would wait for; None where it would start on its own (they are
    cached, or its grid is coarse enough already) or its game solves none.
    Solves nothing, but refuses a scenario its ground station would."""
    return _CtfGame(scenario, provisional=True).awaiting() if is_ctf(scenario) else None


def unsolved(scenario: Scenario) -> bool:
    """Whether ``scenario`` is a capture-the-flag game whose own sets are not
    in the cache yet: its first run, on a fresh clone perhaps."""
    if not is_ctf(scenario):
        return False
    game = _CtfGame(scenario)
    return not stored(game.own(), game.table.stages)


@dataclass
class Cast:
    """Who plays a scenario: the ground station's ``referee``, ``guidance``
    and UAV ``tasking`` (None where the cast has no ground station or no
    UAV), the ``people`` and the ``uavs``; ``awaited``, the sets the
    guidance answers from provisional ones until they are solved, and
    ``adopt(queries)``, which hands them to the guidance and UAV tasking;
    ``warm_up()``, which readies the guidance's compiled code off the game's
    path (see ``GuidanceService.warm_up``)."""

    people: dict[str, HumanAgent]
    referee: Referee | None = None
    guidance: GuidanceService | None = None
    tasking: list = field(default_factory=list)
    uavs: dict[str, UavAgent] = field(default_factory=dict)
    awaited: AwaitedSets | None = None
    adopt: Callable[[CtfQueries], None] | None = None
    warm_up: Callable[[], None] | None = None

    @property
    def ground(self) -> list:
        """The ground station's agents."""
        return [a for a in (self.referee, self.guidance, *self.tasking) if a is not None]

    @property
    def agents(self) -> list:
        """In the order the runtimes start and tick them."""
        return self.ground + list(self.people.values()) + list(self.uavs.values())


def build_cast(
    scenario: Scenario,
    profile: Profile,
    seed: int,
    *,
    people=None,
    uavs=None,
    ground: bool = True,
    ctf_progress=None,
    judge: str = "truth",
    autopilots=None,
    uav_truth: bool = True,
    provisional: bool = False,
    clock=None,
) -> Cast:
    """The agents of ``scenario``: the people named in ``people`` and the
    UAVs named in ``uavs`` (default: all of both if ``people`` is None, else
    no UAV), each UAV flying in-process on the simulated autopilot unless
    ``autopilots`` gives it another (and publishing its telemetry as truth
    with ``uav_truth``: not for a real vehicle); and,
    with ``ground``, the ground station's referee (judging on ``judge``: the
    simulation's truth, or the fixes when the players are real), guidance
    service and UAV tasking. With ``provisional``, a capture-the-flag
    ground station whose sets are not in the cache answers from coarser
    ones, solved at once, and names the sets it awaits (``Cast.awaited``);
    the other games solve in well under a second and ignore it. ``clock``
    is what the plug-ins (behaviours, guidance methods, tasking policies)
    are held to their budgets on (live runs: the wall clock; None, in
    simulation: no budget, see ``agents.guard``)."""
    game = scenario.game_entry.factory(scenario, provisional=provisional, seed=seed, clock=clock)
    if scenario.uavs and not isinstance(game, _CtfGame):
        raise ScenarioError(f"{scenario.source}: UAVs fly in capture-the-flag games only")
    chosen = scenario.ids if people is None else list(people)
    flown = ([u.id for u in scenario.uavs] if people is None else []) if uavs is None else list(uavs)
    crowd = {a: game.person(scenario.agent(a), profile, seed, clock) for a in chosen}
    autopilots = dict(autopilots or {})
    fleet = {}
    for u in flown:
        spec = _uav_spec(scenario, u)
        assert isinstance(game, _CtfGame)  # the scenario has UAVs, so it is a capture-the-flag game
        autopilot = autopilots[u] if u in autopilots else simulated_autopilot(scenario, spec, seed)
        fleet[u] = game.uav(spec, autopilot, truth=uav_truth)
    if not ground:
        return Cast(crowd, uavs=fleet)
    if judge not in ("truth", "fixes"):
        raise ScenarioError(f"the referee judges on truth or fixes, not {judge!r}")
    tasking = [game.tasker()] if scenario.uavs and isinstance(game, _CtfGame) else []
    guidance = game.guidance(profile, ctf_progress)
    adopt = game.adopt if isinstance(game, _CtfGame) and game.awaited is not None else None
    referee = game.referee(on_truth=judge == "truth")
    starts = {a.id: a.start for a in scenario.agents}
    warm_up = functools.partial(guidance.warm_up, starts)
    return Cast(crowd, referee, guidance, tasking, fleet, game.awaited, adopt, warm_up)


def ctf_of(scenario: Scenario) -> _CtfGame:
    """The capture-the-flag game of ``scenario`` as its ground station sets it up."""
    if not is_ctf(scenario):
        raise ScenarioError(f"{scenario.source}: this needs a capture-the-flag game, not {scenario.game}")
    return _CtfGame(scenario)


def is_ctf(scenario: Scenario) -> bool:
    """Whether ``scenario`` plays the built-in capture-the-flag game, whose
    sets are solved ahead, cached and calibrated."""
    return scenario.game_entry.factory is _CtfGame


def simulated_autopilot(scenario: Scenario, spec, seed: int) -> SimulatedAutopilot:
    """The in-process autopilot of UAV ``spec``, its home where it takes off."""
    home = scenario.map.to_geodetic(*spec.start)
    airframe = Airframe(max_speed=spec.speed, max_accel=spec.accel)
    return SimulatedAutopilot(home, airframe=airframe, rng=stream(seed, spec.id, "uav"))


def _uav_spec(scenario: Scenario, uav: str):
    for spec in scenario.uavs:
        if spec.id == uav:
            return spec
    raise ScenarioError(
        f"{scenario.source}: there is no UAV {uav!r}; the UAVs are {', '.join(u.id for u in scenario.uavs) or 'none'}"
    )


class _CtfGame(Game):
    """Capture-the-flag, 1 vs 1, with a flag and a return region (thesis 3.1.1, 3.5)."""

    Options = CtfRules
    teams = ("attacker", "defender")
    answers = frozenset({"plain", "worst_case", "calibrated"})
    default_guidance = "calibrated"

    def __init__(self, scenario: Scenario, provisional: bool = False, seed: int = 0, clock=None) -> None:
        attackers, defenders = scenario.team("attacker"), scenario.team("defender")
        self.seed, self.clock = seed, clock
        if len(attackers) != 1 or len(defenders) != 1:
            raise ScenarioError(f"{scenario.source}: capture-the-flag is 1 vs 1: one attacker and one defender")
        self.scenario = scenario
        self.attacker, self.defender = attackers[0], defenders[0]
        game_map, r = scenario.map, _rules_of(scenario, CtfRules)
        self.table = r
        self.rules = default_rules(
            game_map,
            self.attacker.speed,
            self.defender.speed,
            capture_radius=r.capture_radius,
            capture_time=r.capture_time,
            return_time=r.return_time,
        )
        coarse = unresolved_capture(game_map, r.grid, self.rules.capture_radius)
        if coarse is not None:
            raise ScenarioError(
                f"{scenario.source}: rules.capture_radius {self.rules.capture_radius:g} m is less than a cell of the "
                f"{r.grid}-point grid on map {game_map.name} ({coarse[0]:.2f} m), too coarse to resolve capture; "
                f"raise rules.grid to at least {coarse[1]} or the radius"
            )
        asked = r.provisional_grid
        if asked:
            coarse = unresolved_capture(game_map, asked, self.rules.capture_radius)
            if asked >= r.grid:
                raise ScenarioError(f"{scenario.source}: rules.provisional_grid {asked} is not below rules.grid")
            if coarse is not None:
                raise ScenarioError(
                    f"{scenario.source}: rules.provisional_grid {asked} is too coarse to resolve capture "
                    f"(use {coarse[1]})"
                )
        self.provisional = provisional_grid(game_map, r.grid, self.rules.capture_radius, asked) if provisional else None
        self.awaited: AwaitedSets | None = None
        self.flag = shapely.union_all([g.geometry for g in game_map.regions_with_role("flag")])
        self.home = shapely.union_all([g.geometry for g in game_map.regions_with_role("return")])
        self.flag_taken = r.stages == "return"
        self.phase = "return" if self.flag_taken else "capture"
        self.goals = {"capture": self.flag, "return": self.home}
        self._navigator: Navigator | None = None
        self._solved: CtfQueries | None = None
        self._tasker: UavTasker | None = None
        self._advisor: CtfAdvisor | None = None
        teams = {a.id: a.team for a in scenario.agents} | {u.id: u.team for u in scenario.uavs}
        self.sight = Sight(
            game_map, teams, line_of_sight=r.visibility == "line-of-sight", uavs=[u.id for u in scenario.uavs]
        )

    def solved(self, progress=None) -> CtfQueries:
        """The game's sets; provisional ones while its own are not in the cache, if so asked."""
        if self._solved is None:
            s = self.scenario
            self.awaited = self.awaiting()
            grid = self.table.grid if self.awaited is None else self.awaited.provisional
            game = CtfGame(s.map, grid, self.rules, device=self.table.device)
            found = load_or_solve(game, self.table.stages, progress=progress)
            self._solved = CtfQueries(found.solution)
        return self._solved

    def own(self) -> CtfGame:
        """The game on the scenario's own grid."""
        return CtfGame(self.scenario.map, self.table.grid, self.rules, device=self.table.device)

    def awaiting(self) -> AwaitedSets | None:
        """The sets to answer from provisional ones until they are solved, if any."""
        own, stages = self.own(), self.table.stages
        if self.provisional is None or stored(own, stages):
            return None
        return AwaitedSets(own, stages, self.provisional)

    def adopt(self, queries: CtfQueries) -> None:
        """Answer from ``queries`` from now on, in the guidance and the UAV tasking alike."""
        self._solved = queries
        for user in (self._advisor, self._tasker):
            if user is not None:
                user.adopt(queries)

    def referee(self, on_truth: bool = True) -> Referee:
        contest = Contest(
            runners=(self.attacker.id,),
            chasers=(self.defender.id,),
            capture_radius=self.rules.capture_radius,
            time_limit=self.scenario.time_limit,
            teams=("attacker", "defender"),
            targets=(("home", self.home),) if self.flag_taken else (("flag", self.flag), ("home", self.home)),
            forbidden=(("flag", self.flag), ("return", self.home)),
            flag_taken=self.flag_taken,
        )
        return Referee(self.scenario.name, self.scenario.map, contest, on_truth=on_truth, rejoin=self.scenario.lease)

    def guidance(self, profile: Profile, progress=None) -> GuidanceService:
        s = self.scenario
        self._advisor = CtfAdvisor(
            s.map,
            self.solved(progress),
            attacker=self.attacker.id,
            defender=self.defender.id,
            phase=self.phase,
            uncertainty=_uncertainty(s),
            calibration=functools.partial(self.calibration, profile),
            alpha=s.alpha,
            defender_quantile=s.defender_quantile,
            ablate=s.ablate,
        )
        advisor: CtfAdvisor | SearchAdvisor = self._advisor
        if s.uavs:
            advisor = SearchAdvisor(self._advisor, self.tasker(), self.sight.side("attacker"))
        sight = self.sight if self.sight.line_of_sight or s.uavs else None
        return guidance_service(s, advisor, profile, self.seed, self.clock, sight=sight)

    def calibration(self, profile: Profile) -> Calibration | None:
        """The game's calibration on ``profile``, if ``bearcat calibrate`` made
        one; if not, the log says so, once per process (a study's worker plays
        many games of one scenario)."""
        s = self.scenario
        found = load_calibration(self.own(), profile, s.alpha, s.ablate)
        missing = (s.name, profile.name, s.alpha, s.ablate)
        if found is None and missing not in _UNCALIBRATED:
            _UNCALIBRATED.add(missing)
            log.warning(
                "%s: no calibration of map %s on profile %s at alpha %g yet: calibrated guidance takes its margin "
                "from the tracker's belief until '%s' has run",
                s.name,
                s.map.name,
                profile.name,
                s.alpha,
                calibrate_command(s.name, profile.name, s.ablate),
            )
        return found

    def tasker(self) -> UavTasker:
        """The tasking of the attacking side's UAVs (thesis 6.2 searches for
        the defender), made once: the guidance shows what it tracks."""
        if self._tasker is None:
            s = self.scenario
            if s.uav_of("defender"):
                raise ScenarioError(
                    f"{s.source}: only the attacker's side flies UAVs (thesis 6.2); "
                    f"uav {s.uav_of('defender')[0].id} is the defender's"
                )
            chosen = [s.tasking_of(u.id) for u in s.uavs]
            policies = sorted({c.entry.name for c in chosen})
            if len(policies) > 1 or any(c.options != chosen[0].options for c in chosen):
                raise ScenarioError(
                    f"{s.source}: the UAVs of a side search together, by one policy with one set of options; "
                    f"these mix {' and '.join(policies) if len(policies) > 1 else 'its options'}"
                )
            guard = Guard(TASKER, chosen[0].entry.name, PERIOD / 4, self.clock)
            rng = stream(self.seed, TASKER, "tasking")
            made = _made(chosen[0].entry, "next_point")
            policy = guard.call(0.0, chosen[0].entry.factory, chosen[0].options, rng, check=made, timed=False)
            self._tasker = UavTasker(
                s.name,
                s.map,
                uavs=[Uav(u.id, u.speed, u.camera_radius, u.altitude) for u in s.uavs],
                attacker=self.attacker.id,
                defender=self.defender.id,
                defender_start=self.defender.start,
                defender_speed=self.defender.speed,
                policy=policy,
                entry=chosen[0].entry,
                ctf=self.solved(),
                sight=self.sight,
                name=TASKER,
                guard=guard,
            )
        return self._tasker

    def uav(self, spec, autopilot, truth: bool = True) -> UavAgent:
        opponents = tuple(a.id for a in self.scenario.agents if a.team != spec.team)
        return UavAgent(
            self.scenario.name,
            spec.id,
            autopilot,
            altitude=spec.altitude,
            camera_radius=spec.camera_radius,
            watch=opponents,
            fix_rate=spec.fix_rate,
            failsafe=spec.failsafe,
            link_timeout=spec.link_timeout,
            truth=truth,
            steer=spec.steer,
            speed=spec.speed,
        )

    def person(self, spec, profile: Profile, seed: int, clock=None) -> HumanAgent:
        if self._navigator is None:
            self._navigator = navigator(self.scenario.map)
        attacking = spec.team == "attacker"
        opponent = self.defender if attacking else self.attacker
        forbidden = None if attacking else self.flag.union(self.home)
        situation = Situation(spec.id, spec.team, (opponent.id,), self.goals[self.phase], forbidden, self._navigator)
        return _person(
            self.scenario, spec, profile, seed, situation, self.goals, self.phase, keep_out=forbidden, clock=clock
        )


class _PursuitGame(Game):
    """Cooperative pursuit in a convex field: the pursuers capture the evader, or it lasts (thesis 5.4).

    Pursuers see the evader's safe-reachable set and their heading; the
    pursuers win by capture, the evader by lasting the time limit."""

    Options = PursuitRules
    teams = ("evader", "pursuer")
    awaited = None

    def __init__(self, scenario: Scenario, provisional: bool = False, seed: int = 0, clock=None) -> None:
        self.scenario = scenario
        free = scenario.map.free_space
        if not abs(free.area - free.convex_hull.area) <= 1e-9 * free.area:
            raise ScenarioError(
                f"{scenario.source}: pursuit guidance needs a convex field; map {scenario.map.name} is not"
            )
        evaders = scenario.team("evader")
        if len(evaders) != 1:
            raise ScenarioError(f"{scenario.source}: a pursuit game has one evader")
        self.evader = evaders[0]
        self.seed, self.clock = seed, clock
        self.pursuers = scenario.team("pursuer")
        self.table = _rules_of(scenario, PursuitRules)
        self._navigator: Navigator | None = None

    def referee(self, on_truth: bool = True) -> Referee:
        contest = Contest(
            runners=(self.evader.id,),
            chasers=tuple(p.id for p in self.pursuers),
            capture_radius=self.table.capture_radius,
            time_limit=self.scenario.time_limit,
            teams=("evader", "pursuer"),
            lasting_wins=True,
        )
        return Referee(self.scenario.name, self.scenario.map, contest, on_truth=on_truth, rejoin=self.scenario.lease)

    def guidance(self, profile: Profile, progress=None) -> GuidanceService:
        s = self.scenario
        advisor = PursuitAdvisor(s.map, evader=self.evader.id, pursuers=[p.id for p in self.pursuers])
        return guidance_service(s, advisor, profile, self.seed, self.clock)

    def person(self, spec, profile: Profile, seed: int, clock=None) -> HumanAgent:
        if self._navigator is None:
            self._navigator = navigator(self.scenario.map)
        opponents = tuple(p.id for p in self.pursuers) if spec.team == "evader" else (self.evader.id,)
        situation = Situation(spec.id, spec.team, opponents, None, None, self._navigator)
        return _person(self.scenario, spec, profile, seed, situation, {}, "capture", clock=clock)


class _ReachAvoidGame(Game):
    """Open-loop reach-avoid: one attacker reaches the targets in turn past many defenders (thesis 4).

    The defenders win by capture or when time runs out."""

    Options = ReachAvoidRules
    teams = ("attacker", "defender")
    answers = frozenset({"plain", "worst_case"})
    default_guidance = "worst-case"
    awaited = None

    def __init__(self, scenario: Scenario, provisional: bool = False, seed: int = 0, clock=None) -> None:
        self.scenario = scenario
        attackers = scenario.team("attacker")
        if len(attackers) != 1:
            raise ScenarioError(f"{scenario.source}: a reach-avoid game has one attacker")
        self.attacker = attackers[0]
        self.defenders = scenario.team("defender")
        self.seed, self.clock = seed, clock
        self.table = _rules_of(scenario, ReachAvoidRules)
        names = self.table.targets
        self.targets = [(n, scenario.map.region(n).geometry) for n in names]
        self.goals = {"capture": self.targets[0][1], "return": self.targets[-1][1]}
        xmin, ymin, xmax, ymax = scenario.map.bounds
        self.radius = self.table.capture_radius or 0.005 * max(xmax - xmin, ymax - ymin)
        self._navigator: Navigator | None = None

    def referee(self, on_truth: bool = True) -> Referee:
        contest = Contest(
            runners=(self.attacker.id,),
            chasers=tuple(d.id for d in self.defenders),
            capture_radius=self.radius,
            time_limit=self.scenario.time_limit,
            teams=("attacker", "defender"),
            targets=tuple(self.targets),
        )
        return Referee(self.scenario.name, self.scenario.map, contest, on_truth=on_truth, rejoin=self.scenario.lease)

    def guidance(self, profile: Profile, progress=None) -> GuidanceService:
        s = self.scenario
        xmin, ymin, xmax, ymax = s.map.bounds
        advisor = ReachAvoidAdvisor(
            s.map,
            attacker=self.attacker.id,
            defenders=[d.id for d in self.defenders],
            targets=self.table.targets,
            speeds={a.id: a.speed for a in s.agents},
            capture_radius=self.radius,
            spacing=self.table.spacing or max(xmax - xmin, ymax - ymin) / 200,
            uncertainty=_uncertainty(s),
        )
        return guidance_service(s, advisor, profile, self.seed, self.clock)

    def person(self, spec, profile: Profile, seed: int, clock=None) -> HumanAgent:
        if self._navigator is None:
            self._navigator = navigator(self.scenario.map)
        opponents = tuple(d.id for d in self.defenders) if spec.team == "attacker" else (self.attacker.id,)
        situation = Situation(spec.id, spec.team, opponents, self.goals["capture"], None, self._navigator)
        return _person(self.scenario, spec, profile, seed, situation, self.goals, "capture", clock=clock)


def guidance_service(scenario: Scenario, advisor, profile: Profile, seed: int, clock=None, sight=None):
    """The guidance service of ``scenario``: each aided agent's guidance
    method, answering from ``advisor``, the game's, held to its budget on
    ``clock`` (None: no budget); trackers of every agent on ``profile``'s
    GPS where some agent's method reads them (``TRACKS``)."""
    budget = 0.25 / scenario.guidance_rate if scenario.guidance_budget is None else scenario.guidance_budget
    methods = {}
    for agent in (a for a in scenario.agents if a.aided):
        chosen = scenario.guidance_of(agent.id)
        guard = Guard(agent.id, chosen.entry.name, budget, clock)
        rng = stream(seed, agent.id, "guidance")
        made = _made(chosen.entry, "advise")
        methods[agent.id] = (guard.call(0.0, chosen.entry.factory, chosen.options, rng, check=made, timed=False), guard)
    tracks = any(chosen.entry.has(TRACKS) for chosen in scenario.guidance.values())
    return GuidanceService(
        scenario.name,
        scenario.map,
        scenario.ids,
        advisor=advisor,
        methods=methods,
        teams={a.id: a.team for a in scenario.agents},
        speeds={a.id: a.speed for a in scenario.agents} | {u.id: u.speed for u in scenario.uavs},
        rate=scenario.guidance_rate,
        sight=sight,
        uncertainty=_uncertainty(scenario),
        tracking=tracking(scenario, profile) if tracks else None,
    )


def tracking(scenario: Scenario, profile: Profile) -> Callable[[], Trackers]:
    """Makes the trackers of calibrated guidance: the profile's GPS and
    compass, and each person's motion from their speed, heading error and
    report rate (UAVs get the default); less what ``guidance.ablate``
    switches off of them."""
    motions = {a.id: Motion.of(a.speed, a.heading_error, 1.0 / a.fix_rate) for a in scenario.agents}
    if "manoeuvre" in scenario.ablate:
        motions = {agent: motion.walking_only() for agent, motion in motions.items()}
    gps = profile.gps.as_white() if "bias" in scenario.ablate else profile.gps
    to_now = "prediction" not in scenario.ablate
    return functools.partial(Trackers, scenario.map, gps, profile.compass, motions=motions, to_now=to_now)


def _uncertainty(scenario: Scenario) -> Uncertainty:
    """How far each player and UAV may be from its last fix, at its top speed."""
    speeds = {a.id: a.speed for a in scenario.agents} | {u.id: u.speed for u in scenario.uavs}
    return Uncertainty(speeds, scenario.guidance_confidence)


BUILTINS: dict[str, type] = {"ctf": _CtfGame, "reach-avoid": _ReachAvoidGame, "pursuit": _PursuitGame}
"""The built-in entries of ``game.GAMES``, by the names scenarios give them."""


def _rules_of(scenario: Scenario, kind: type[_Rules]) -> _Rules:
    """The rules of ``scenario``, which its game reads as ``kind``."""
    rules = scenario.rules
    assert isinstance(rules, kind), f"a {scenario.game} scenario has {type(rules).__name__}"
    return rules


def _person(
    scenario, spec, profile: Profile, seed: int, situation, goals, phase, keep_out=None, clock=None
) -> HumanAgent:
    """The person ``spec`` plays, its behaviour held to its budget on ``clock`` (None: no budget)."""
    walker = Walker(
        scenario.map,
        spec.start,
        speed=spec.speed,
        reaction=spec.reaction,
        heading_error=spec.heading_error,
        keep_out=keep_out,
        rng=stream(seed, spec.id, "walker"),
    )
    phone = Phone(
        spec.id,
        scenario.map,
        gps=profile.gps,
        compass=profile.compass,
        rng=stream(seed, spec.id, "phone"),
        fix_rate=spec.fix_rate,
    )
    chosen = scenario.behaviour_of(spec.id)
    budget = HumanAgent.period / 4 if spec.budget is None else spec.budget
    guard = Guard(spec.id, chosen.entry.name, budget, clock)
    rng = stream(seed, spec.id, "behaviour")
    made = _made(chosen.entry, "decide")
    behaviour = guard.call(0.0, chosen.entry.factory, chosen.options, rng, check=made, timed=False)
    return HumanAgent(
        scenario.name,
        walker,
        phone,
        behaviour,
        situation,
        goals=goals,
        phase=phase,
        traits=chosen.entry.traits,
        guard=guard,
    )


def _made(entry: Entry, method: str):
    """The check of what ``entry``'s factory made: an object with the protocol's ``method``."""

    def check(made) -> str | None:
        return None if callable(getattr(made, method, None)) else f"made {type(made).__name__}, which has no {method}"

    return check
