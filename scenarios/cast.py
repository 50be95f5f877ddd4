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
from agents.ground_station.guidance import CtfGuidanceService
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
    referee: Referee
    guidance: object
    people: dict[str, HumanAgent]
    contest: Contest

    @property
    def agents(self) -> list:
        """In the order the runtimes start and tick them."""
        return [self.referee, self.guidance, *self.people.values()]


def cast(scenario: Scenario, profile: Profile, seed: int, *, ctf_progress=None) -> Cast:
    if scenario.game != "ctf":
        raise ScenarioError(f"{scenario.source}: running {scenario.game} games is not supported yet; ctf is")
    return _ctf(scenario, profile, seed, ctf_progress)


def _ctf(scenario: Scenario, profile: Profile, seed: int, progress) -> Cast:
    attackers, defenders = scenario.team("attacker"), scenario.team("defender")
    if len(attackers) != 1 or len(defenders) != 1:
        raise ScenarioError(f"{scenario.source}: capture-the-flag is 1 vs 1: one attacker and one defender")
    attacker, defender = attackers[0], defenders[0]
    game_map, r = scenario.map, scenario.rules
    rules = default_rules(
        game_map, attacker.speed, defender.speed,
        capture_radius=r["capture_radius"], capture_time=r["capture_time"], return_time=r["return_time"],
    )  # fmt: skip
    solved = load_or_solve(CtfGame(game_map, r["grid"], rules), r["stages"], progress=progress)
    flag = shapely.union_all([g.geometry for g in game_map.regions_with_role("flag")])
    home = shapely.union_all([g.geometry for g in game_map.regions_with_role("return")])
    flag_taken = r["stages"] == "return"
    contest = Contest(
        runners=(attacker.id,), chasers=(defender.id,), capture_radius=rules.capture_radius,
        time_limit=scenario.time_limit, teams=("attacker", "defender"),
        targets=(("home", home),) if flag_taken else (("flag", flag), ("home", home)),
        forbidden=(("flag", flag), ("return", home)), flag_taken=flag_taken,
    )  # fmt: skip
    phase = "return" if flag_taken else "capture"
    guidance = CtfGuidanceService(
        scenario.name, game_map, CtfGuidance(solved.solution), attacker=attacker.id, defender=defender.id,
        aided={a.id: a.aided for a in scenario.agents}, rate=scenario.guidance_rate, phase=phase,
    )  # fmt: skip
    navigator = Navigator(game_map)
    goals = {"capture": flag, "return": home}
    people = {}
    for spec, opponent, forbidden in ((attacker, defender, None), (defender, attacker, flag.union(home))):
        situation = behaviours.Situation(spec.id, spec.team, (opponent.id,), goals[phase], forbidden, navigator)
        people[spec.id] = _person(scenario, spec, profile, seed, situation, goals, phase, keep_out=forbidden)
    return Cast(Referee(scenario.name, game_map, contest), guidance, people, contest)


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
