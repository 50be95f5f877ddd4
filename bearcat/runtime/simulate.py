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
from bearcat.runtime.world import world_of
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
    seed, profile, plan = world.seed, world.profile, world.plan
    if (why := refusal(plan, "simulate")) is not None:
        raise FaultError(why)
    if players is None:
        players = world.cast(ctf_progress=ctf_progress)
    env = simpy.Environment()
    record = EventLog(events)

    def where(peer: str):
        person = players.people.get(peer)
        return None if person is None else tuple(person.walker.position)

    shim = world.shim(record.impaired, where, (*(a.name for a in players.ground), LAUNCHER))

    def arrive(call, payload):
        return lambda _event: call(payload)

    def deliver(sender, receiver, key, payload, call):
        if payload is None:  # liveliness
            call(None)
            return
        for d in shim.transmit(sender, receiver, key, payload, env.now, token=call):
            env.timeout(max(d.at - env.now, 0.0)).callbacks.append(arrive(call, d.payload))

    bus = InProcessBus(deliver)
    dispatch = Dispatcher(record, lambda: env.now)
    final: dict = {}

    playing = {agent.name: agent for agent in players.agents}  # a restart puts a new agent in its place

    def receiver(name):
        def receive(key, payload, sender):
            if injector is None:
                dispatch.receive(playing[name], key, payload, sender)
            else:
                injector.arrive(name, lambda: dispatch.receive(playing[name], key, payload, sender))

        return receive

    def watcher(name):
        return lambda key, alive: dispatch.peer(playing[name], key, alive)

    sessions = {}
    for agent in players.agents:
        session = sessions[agent.name] = bus.session(agent.name)
        dispatch.attach(agent, session)
        for expr in agent.subscriptions:
            session.subscribe(expr, receiver(agent.name))
        for expr in agent.watches:
            session.subscribe_liveliness(expr, watcher(agent.name))
    for agent in players.agents:
        sessions[agent.name].declare_token(keys.alive(scenario.name, agent.role, agent.name))

    launcher = bus.session(LAUNCHER)
    launcher_inbox = Inbox(LAUNCHER)
    done = env.event()

    def on_state(key, payload, sender):
        state = launcher_inbox.accept(key, payload)
        if injector is not None and state is not None:
            injector.saw(state, env.now)
        if isinstance(state, GameState) and state.phase == "ended" and not done.triggered:
            final["state"] = state
            done.succeed()

    launcher.subscribe(keys.state(scenario.name), on_state)

    def ticker(agent):
        dispatch.start(agent)
        while playing[agent.name] is agent:
            yield env.timeout(agent.period)
            if playing[agent.name] is agent and (injector is None or injector.running(agent.name)):
                dispatch.tick(agent)

    def poller():
        while True:
            yield env.timeout(POLL)
            for call, d in shim.poll(env.now):
                env.timeout(max(d.at - env.now, 0.0)).callbacks.append(arrive(call, d.payload))

    def inspector():
        while True:
            yield env.timeout(POLL)
            inspect(env.now, players)

    def halt(reason: str) -> None:
        if not done.triggered:
            final["halted"] = reason
            done.succeed()

    def rebuild(peer: str, old: list) -> list:
        """The agents of ``peer`` built afresh, as a restarted process builds them;
        a UAV's vehicle flies on through its peer's restart."""
        if peer == GROUND:
            return world.cast(people=[], ground=True).ground
        if peer in players.uavs:
            pilots = {peer: old[0].autopilot}
            return list(world.cast(people=[], uavs=[peer], ground=False, autopilots=pilots).uavs.values())
        return list(world.cast(people=[peer], ground=False).people.values())

    injector = None
    if plan:
        injector = SimulatedFaults(
            env,
            scenario,
            plan,
            agents=playing,
            ground=[a.name for a in players.ground],
            dispatch=dispatch,
            shim=shim,
            record=record,
            spawn=lambda agent: env.process(ticker(agent)),
            rebuild=rebuild,
            halt=halt,
        )
    for agent in players.agents:
        env.process(ticker(agent))
    if inspect is not None:
        env.process(inspector())
    if world.zones is not None or plan:
        env.process(poller())
    start = Control(t=0.0, command="start", seq=1)
    record.sent(0.0, LAUNCHER, keys.control(scenario.name), start)
    launcher.put(keys.control(scenario.name), encode(start))
    env.run(until=env.any_of([done, env.timeout(scenario.time_limit + GRACE)]))

    state = final.get("state")
    outcome = Outcome(
        scenario=scenario.name,
        seed=seed,
        netem=profile.name,
        transport=world.transport,
        winner=state.winner if state else None,
        reason=state.reason
        if state
        else final.get("halted", f"no result within {scenario.time_limit + GRACE:g} s of game time"),
        elapsed=state.elapsed if state else env.now,
        ended=state is not None,
        flag_holder=state.flag_holder if state else None,
        captured=list(state.captured) if state else [],
        counts=dict(sorted(record.counts.items())),
        drops=dispatch.drops,
        failures=dict(sorted(dispatch.failures.items())),
        plugin_faults=dict(sorted(dispatch.plugin_faults.items())),
        notes=_notes(players),
        faults=[] if injector is None else injector.applied,
    )
    record.note(env.now, "outcome", **{k: v for k, v in vars(outcome).items() if k != "counts"})
    record.close()
    for session in sessions.values():
        session.close()
    return outcome


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
