"""The simulation runtime: every peer in one process, in virtual time.

A simpy environment drives the agents (each ticks at its own period from
t = 0) over the in-process bus. Every message is encoded by its sender and
decoded by each receiver, as on Zenoh, and crosses the netem shim of its
directed link, which decides when (and whether, and how often) it arrives;
arrivals are scheduled in virtual time. The agents are driven as in live
runs (scenarios/dispatch.py: an agent's exception is recorded and the game
goes on). The launcher's part is played here too: liveliness tokens for every peer, the start command at t = 0, and the
end when the referee says the game is over. For a seed the run is
deterministic, down to every line of its event log. A fault plan (the
scenario's own, or one given) is applied in virtual time
(``simulated_faults``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import simpy

from bearcat.agents.ground_station.event_log import EventLog
from bearcat.bus import keys
from bearcat.bus.codec import Inbox, encode
from bearcat.bus.inprocess import InProcessBus
from bearcat.bus.messages import Control, GameState
from bearcat.runtime.dispatch import Dispatcher
from bearcat.runtime.simulated_faults import SimulatedFaults
from bearcat.runtime.world import World, world_of
from bearcat.scenarios.cast import Cast
from bearcat.scenarios.faults import GROUND, LAUNCHER, FaultError, refusal
from bearcat.scenarios.schema import Scenario

log = logging.getLogger(__name__)

GRACE = 5.0  # s of game time past the limit before a run that never ended is cut
POLL = 0.1  # s between releases of messages held in dead zones


@dataclass
class Outcome:
    """How a run ended: ``winner`` (a team, None if nobody won), ``reason``,
    ``elapsed`` seconds of game time, the final ``state`` and message counts;
    ``netem`` and ``transport`` the network it was played on."""

    scenario: str
    seed: int
    netem: str
    transport: str
    winner: str | None
    reason: str
    elapsed: float
    ended: bool
    flag_holder: str | None = None
    captured: list[str] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    drops: dict[str, dict[str, int]] = field(default_factory=dict)
    failures: dict[str, int] = field(default_factory=dict)
    plugin_faults: dict[str, int] = field(default_factory=dict)  # "agent/plug-in/fault" -> how many (agents.guard)
    notes: dict = field(default_factory=dict)
    faults: list[dict] = field(default_factory=list)  # each fault applied: its index, kind, peers and time


def simulate(
    scenario: Scenario,
    *,
    seed: int | None = None,
    netem: str | None = None,
    transport: str | None = None,
    events: str | Path | None = None,
    ctf_progress=None,
    inspect=None,
    players: Cast | None = None,
    faults: tuple | None = None,
) -> Outcome:
    """Play ``scenario`` once; ``events`` is the path of the event log to
    write. ``inspect(now, players)``, if given, looks at every agent's state
    ten times a second (tests check invariants against the truth with it).
    ``players`` plays instead of the cast ``build_cast`` makes for the seed
    and network profile (built for the same ones, with an agent swapped or
    wrapped). ``netem`` and ``transport`` play it on another network than
    the scenario's. ``faults`` is the fault plan to apply instead of the
    scenario's own."""
    world = world_of(scenario, seed=seed, netem=netem, transport=transport, plan=faults)
    if (why := refusal(world.plan, "simulate")) is not None:
        raise FaultError(why)
    if players is None:
        players = world.cast(ctf_progress=ctf_progress)
    return Simulation(world, players, EventLog(events)).play(inspect)


class Simulation:
    """One game of ``world`` played by ``players`` in virtual time, written
    to ``record``: the in-process bus and its network shim, the agents'
    sessions, the launcher's part and the fault plan's injector, set up in
    that order, so that the same seed schedules the same events."""

    def __init__(self, world: World, players: Cast, record: EventLog) -> None:
        self.world, self.players, self.record = world, players, record
        self.scenario = world.scenario
        self.env = simpy.Environment()
        self.shim = world.shim(record.impaired, self._where, (*(a.name for a in players.ground), LAUNCHER))
        self.bus = InProcessBus(self._deliver)
        self.dispatch = Dispatcher(record, lambda: self.env.now)
        self.final: dict = {}
        self.playing = {agent.name: agent for agent in players.agents}  # a restart puts a new agent in its place
        self.injector: SimulatedFaults | None = None
        self.sessions = {agent.name: self._attach(agent) for agent in players.agents}
        for agent in players.agents:
            self.sessions[agent.name].declare_token(keys.alive(self.scenario.name, agent.role, agent.name))
        self.launcher = self.bus.session(LAUNCHER)
        self.launcher_inbox = Inbox(LAUNCHER)
        self.done = self.env.event()
        self.launcher.subscribe(keys.state(self.scenario.name), self._on_state)
        if world.plan:
            self.injector = SimulatedFaults(
                self.env,
                self.scenario,
                world.plan,
                agents=self.playing,
                ground=[a.name for a in players.ground],
                dispatch=self.dispatch,
                shim=self.shim,
                record=record,
                spawn=lambda agent: self.env.process(self._ticker(agent)),
                rebuild=self._rebuild,
                halt=self._halt,
            )

    def play(self, inspect=None) -> Outcome:
        """Start every agent's clock, start the game at t = 0 and run until
        the referee ends it or its time limit and ``GRACE`` pass; ``inspect``
        as ``simulate`` takes it."""
        env, scenario = self.env, self.scenario
        for agent in self.players.agents:
            env.process(self._ticker(agent))
        if inspect is not None:
            env.process(self._inspector(inspect))
        if self.world.zones is not None or self.world.plan:
            env.process(self._poller())
        start = Control(t=0.0, command="start", seq=1)
        self.record.sent(0.0, LAUNCHER, keys.control(scenario.name), start)
        self.launcher.put(keys.control(scenario.name), encode(start))
        env.run(until=env.any_of([self.done, env.timeout(scenario.time_limit + GRACE)]))
        outcome = self._outcome()
        self.record.note(env.now, "outcome", **{k: v for k, v in vars(outcome).items() if k != "counts"})
        self.record.close()
        for session in self.sessions.values():
            session.close()
        return outcome

    def _where(self, peer: str):
        """Where ``peer`` is, for the dead zones: a person's true position; None for the others."""
        person = self.players.people.get(peer)
        return None if person is None else tuple(person.walker.position)

    def _deliver(self, sender, receiver, key, payload, call) -> None:
        """Carry ``payload`` across the shim of the link, arriving when it says."""
        if payload is None:  # liveliness
            call(None)
            return
        for d in self.shim.transmit(sender, receiver, key, payload, self.env.now, token=call):
            self._arrive_at(d, call)

    def _arrive_at(self, delivery, call) -> None:
        self.env.timeout(max(delivery.at - self.env.now, 0.0)).callbacks.append(lambda _event: call(delivery.payload))

    def _attach(self, agent):
        """``agent``'s session, subscribed to what it hears and watches."""
        session = self.bus.session(agent.name)
        self.dispatch.attach(agent, session)
        name = agent.name
        for expr in agent.subscriptions:
            session.subscribe(expr, lambda key, payload, sender: self._receive(name, key, payload, sender))
        for expr in agent.watches:
            session.subscribe_liveliness(expr, lambda key, alive: self.dispatch.peer(self.playing[name], key, alive))
        return session

    def _receive(self, name: str, key, payload, sender) -> None:
        if self.injector is None:
            self.dispatch.receive(self.playing[name], key, payload, sender)
        else:
            self.injector.arrive(name, lambda: self.dispatch.receive(self.playing[name], key, payload, sender))

    def _on_state(self, key, payload, sender) -> None:
        state = self.launcher_inbox.accept(key, payload)
        if self.injector is not None and state is not None:
            self.injector.saw(state, self.env.now)
        if isinstance(state, GameState) and state.phase == "ended" and not self.done.triggered:
            self.final["state"] = state
            self.done.succeed()

    def _ticker(self, agent):
        self.dispatch.start(agent)
        while self.playing[agent.name] is agent:
            yield self.env.timeout(agent.period)
            if self.playing[agent.name] is agent and (self.injector is None or self.injector.running(agent.name)):
                self.dispatch.tick(agent)

    def _poller(self):
        """Releases what the dead zones and the faults held, as they let it go."""
        while True:
            yield self.env.timeout(POLL)
            for call, d in self.shim.poll(self.env.now):
                self._arrive_at(d, call)

    def _inspector(self, inspect):
        while True:
            yield self.env.timeout(POLL)
            inspect(self.env.now, self.players)

    def _halt(self, reason: str) -> None:
        if not self.done.triggered:
            self.final["halted"] = reason
            self.done.succeed()

    def _rebuild(self, peer: str, old: list) -> list:
        """The agents of ``peer`` built afresh, as a restarted process builds them;
        a UAV's vehicle flies on through its peer's restart."""
        world = self.world
        if peer == GROUND:
            return world.cast(people=[], ground=True).ground
        if peer in self.players.uavs:
            pilots = {peer: old[0].autopilot}
            return list(world.cast(people=[], uavs=[peer], ground=False, autopilots=pilots).uavs.values())
        return list(world.cast(people=[peer], ground=False).people.values())

    def _outcome(self) -> Outcome:
        state, limit = self.final.get("state"), self.scenario.time_limit + GRACE
        return Outcome(
            scenario=self.scenario.name,
            seed=self.world.seed,
            netem=self.world.profile.name,
            transport=self.world.transport,
            winner=state.winner if state else None,
            reason=state.reason if state else self.final.get("halted", f"no result within {limit:g} s of game time"),
            elapsed=state.elapsed if state else self.env.now,
            ended=state is not None,
            flag_holder=state.flag_holder if state else None,
            captured=list(state.captured) if state else [],
            counts=dict(sorted(self.record.counts.items())),
            drops=self.dispatch.drops,
            failures=dict(sorted(self.dispatch.failures.items())),
            plugin_faults=dict(sorted(self.dispatch.plugin_faults.items())),
            notes=_notes(self.players),
            faults=[] if self.injector is None else self.injector.applied,
        )


def _notes(players) -> dict:
    """What a study needs to know of a game besides its outcome: when a
    committing behaviour (a go-no-go attacker, a fake-out) went, when the attacking side
    first saw the defender and by what means."""
    notes = {}
    for name, person in players.people.items():
        if person.committed_at is not None:
            notes[f"{name}.committed_at"] = person.committed_at
    for tasker in players.tasking:
        picture = tasker.picture
        if picture.found_at is not None:
            notes["search.found_at"] = picture.found_at
            notes["search.found_by"] = picture.sightings[0][1]
    return notes
