"""A fault plan applied to a simulated run, in virtual time.

Each peer of the live run has its agents here (the ground station's
referee, guidance and UAV tasking together); a fault acts on the peer as
its live counterpart acts on the process:

- killed or stopped, its agents stop ticking and receiving, and the others
  see its liveliness tokens vanish at once (its TCP connection closed);
- paused, its agents stop ticking and what arrives for them waits in their
  sockets; if the pause outlasts the lease the others see its tokens
  vanish at the lease, what waited is lost with the session, and on
  waking it sees every other token vanish and come back as its session
  reopens; otherwise what waited arrives the moment it wakes;
- restarted, it is killed and, ``duration`` s later, built anew and
  resumed from what it last sent (a walker from its last position, the
  referee from its last state);
- partitioned (or cut off by an outage), its links to the other side are
  down in the shim, and if the cut outlasts the lease each side sees the
  other's tokens vanish, and come back when it heals;
- degraded, its links follow another profile; its clock jumps or drifts
  (its agents are handed their own time); its phone's GPS lies.

Every fault, when it starts and ends, is noted in the event log
(``fault`` and ``fault-end``), and so is every token the launcher (beside
the ground station, on its side of any partition) sees vanish or come
back (``gone``, ``alive``), as the live launcher notes them: the run
checker reads both.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import zenoh

from bearcat.bus import keys
from bearcat.bus.messages import GameState
from bearcat.runtime.recovery import resume
from bearcat.scenarios.fault_effects import apply_network, lie, noted, sides, skewed
from bearcat.scenarios.faults import GROUND, LAUNCHER, Fault

if TYPE_CHECKING:
    import simpy

WATCH = 0.1  # s between looks for the events faults count from


class SimulatedFaults:
    """Applies ``plan`` to the run in ``env``.

    ``agents`` maps each agent's name to the agent now playing it (a
    restart puts a new one there); ``ground`` names the ground station's
    agents; ``spawn(agent)`` starts driving a new agent; ``rebuild(peer,
    old)`` builds a peer's agents afresh; ``halt(reason)`` ends the run, as
    the live launcher does when the ground station dies for good."""

    def __init__(
        self, env, scenario, plan: tuple[Fault, ...], *, agents, ground, dispatch, shim, record, spawn, rebuild, halt
    ) -> None:
        self.env, self.scenario, self.plan = env, scenario, plan
        self.agents, self.dispatch, self.shim, self.record = agents, dispatch, shim, record
        self.spawn, self.rebuild, self.halt = spawn, rebuild, halt
        self.lease = scenario.lease
        # The launcher runs no agent; it watches, beside the ground station.
        self.members: dict[str, list[str]] = {GROUND: list(ground), LAUNCHER: []}
        for name in agents:
            if name not in ground:
                self.members[name] = [name]
        self.peer_of = {a: peer for peer, names in self.members.items() for a in names}
        self.state = dict.fromkeys(self.members, "up")
        self.waiting: dict[str, list] = {peer: [] for peer in self.members}
        self.happened: dict[str, float] = {"start": 0.0}
        self.applied: list[dict] = []
        self._unseen: set[tuple[str, str]] = set()  # (watcher peer, watched peer) whose tokens vanished
        self._events: dict[str, simpy.Event] = {}
        for k, fault in enumerate(plan):
            env.process(self._run(k, fault))
        if any(f.after != "start" for f in plan):
            env.process(self._watch())

    # ------------------------------------------------------------------ what the runtime asks

    def running(self, agent: str) -> bool:
        return self.state[self.peer_of[agent]] == "up"

    def arrive(self, agent: str, call) -> None:
        """A delivery for ``agent``: now if its peer is up, later if paused, never if down."""
        state = self.state[self.peer_of[agent]]
        if state == "up":
            call()
        elif state == "paused":
            self.waiting[self.peer_of[agent]].append(call)

    def saw(self, message, now: float) -> None:
        """The launcher saw ``message`` (events such as the flag being taken come from the state)."""
        if isinstance(message, GameState) and message.flag_holder is not None:
            self._happen("flag-taken", now)

    # ------------------------------------------------------------------ when

    def _run(self, k: int, fault: Fault):
        if fault.after != "start":
            yield self._event(fault.after)
        yield self.env.timeout(max(self.happened[fault.after] + fault.at - self.env.now, 0.0))
        self._apply(k, fault)

    def _event(self, name: str):
        if name not in self._events:
            self._events[name] = self.env.event()
            if name in self.happened:
                self._events[name].succeed()
        return self._events[name]

    def _happen(self, name: str, now: float) -> None:
        if name in self.happened:
            return
        self.happened[name] = now
        self.record.note(now, "happened", name=name)
        event = self._events.get(name)
        if event is not None and not event.triggered:
            event.succeed()

    def _watch(self):
        goers = {f.after.rpartition(".")[0] for f in self.plan if f.after.endswith(".goes")}
        while goers:
            yield self.env.timeout(WATCH)
            for agent in list(goers):
                if self.agents[agent].going:
                    self._happen(f"{agent}.goes", self.env.now)
                    goers.discard(agent)

    def _later(self, delay: float, action) -> None:
        self.env.timeout(delay).callbacks.append(lambda _event: action())

    # ------------------------------------------------------------------ what

    def _apply(self, k: int, fault: Fault) -> None:
        now = self.env.now
        self.applied.append(noted(self.record, k, fault, now))
        ends = fault.ends
        if ends is not None and fault.kind not in ("restart", "partition"):
            self._later(ends, lambda: self.record.note(self.env.now, "fault-end", fault=k, kind=fault.kind))
        getattr(self, "_" + fault.kind)(k, fault, now)

    def _kill(self, k, fault, now) -> None:
        self._down(fault.target, now)
        if fault.target == GROUND:
            self.halt(f"the ground station is gone: fault[{k}] ({fault.describe()})")

    _stop = _kill

    def _restart(self, k, fault, now) -> None:
        self._down(fault.target, now)

        def back():
            old = [self.agents[name] for name in self.members[fault.target]]
            fresh = self.rebuild(fault.target, old)
            for agent in fresh:
                resume(agent, self.record.last, self.scenario.name)
                self.agents[agent.name] = agent
                self.dispatch.attach(agent, self.dispatch.session_of(agent.name))
            self.state[fault.target] = "up"
            self.record.note(self.env.now, "fault-end", fault=k, kind=fault.kind)
            for agent in fresh:
                self.spawn(agent)
            self._show(fault.target, self._others(fault.target), True)
            for peer in self._others(fault.target):
                self._show(peer, [fault.target], True)

        self._later(fault.duration, back)

    def _pause(self, k, fault, now) -> None:
        peer = fault.target
        self.state[peer] = "paused"
        lost = fault.duration >= self.lease
        if lost:
            self._later(self.lease, lambda: self._show(peer, self._others(peer), False))

        def wake():
            self.state[peer] = "up"
            waiting, self.waiting[peer] = self.waiting[peer], []
            if lost:  # the session died with what it held; it reopens, and sees the others come and go
                for other in self._others(peer):
                    self._show(other, [peer], False)
                for other in self._others(peer):
                    self._show(other, [peer], True)
                self._show(peer, self._others(peer), True)
                return
            for call in waiting:
                call()

        self._later(fault.duration, wake)

    def _partition(self, k, fault, now) -> None:
        """Cut the links between peers on different sides; past the lease, each side sees the other go."""
        apply_network(fault, self.shim, now, None if fault.duration is None else now + fault.duration, self._names)
        cut = self.shim.cuts[-1]
        side, rest = sides(fault)
        split = [(a, b) for a in self.members for b in self.members if side.get(a, rest) != side.get(b, rest)]

        def expire():
            if cut.end is None or cut.end - cut.start >= self.lease:
                for watcher, watched in split:
                    self._show(watched, [watcher], False)

        def heal_check():
            if cut.end is not None and cut.end <= self.env.now:
                self.record.note(self.env.now, "fault-end", fault=k, kind="partition")
                for watcher, watched in split:
                    if (watcher, watched) in self._unseen:
                        self._show(watched, [watcher], True)
                return
            self._later(WATCH, heal_check)

        self._later(self.lease, expire)
        self._later(WATCH, heal_check)

    _outage = _partition

    def _heal(self, k, fault, now) -> None:
        apply_network(fault, self.shim, now, None, self._names)

    def _degrade(self, k, fault, now) -> None:
        apply_network(fault, self.shim, now, now + fault.duration, self._names)

    def _clock(self, k, fault, now) -> None:
        names = self.members[fault.target]
        for name in names:
            self.dispatch.clocks[name] = skewed(fault, now)
        if fault.duration is not None:
            self._later(fault.duration, lambda: [self.dispatch.clocks.pop(n, None) for n in names])

    def _gps(self, k, fault, now) -> None:
        self.agents[fault.target].phone.lie = lie(fault)
        if fault.duration is not None:
            self._later(fault.duration, lambda: setattr(self.agents[fault.target].phone, "lie", None))

    # ------------------------------------------------------------------ processes and liveliness

    def _down(self, peer: str, now: float) -> None:
        self.state[peer] = "down"
        self.waiting[peer] = []
        self._show(peer, self._others(peer), False)

    def _names(self, peer: str) -> list[str]:
        """The session names of ``peer``'s agents (the launcher's own)."""
        return self.members[peer] or [peer]

    def _others(self, peer: str) -> list[str]:
        return [p for p in self.members if p != peer]

    def _show(self, watched: str, watchers: list[str], alive: bool) -> None:
        """``watchers`` see the tokens of ``watched`` come (``alive``) or go."""
        now = self.env.now
        tokens = [keys.alive(self.scenario.name, self.agents[a].role, a) for a in self.members[watched]]
        for watcher in watchers:
            pair = (watcher, watched)
            if alive == (pair not in self._unseen):
                continue  # already so
            (self._unseen.discard if alive else self._unseen.add)(pair)
            if self.state[watcher] != "up":
                continue
            if watcher == LAUNCHER:
                for token in tokens:
                    self.record.note(now, "alive" if alive else "gone", key=token)
            for name in self.members[watcher]:
                agent = self.agents[name]
                for token in tokens:
                    if any(zenoh.KeyExpr(w).intersects(zenoh.KeyExpr(token)) for w in agent.watches):
                        self.dispatch.peer(agent, token, alive)
