"""The live runtime: one peer process, its agents driven by the wall clock
over Zenoh.

Zenoh's callbacks run on its own threads; they only hand each sample to the
asyncio loop, where the receiving end's netem shim decides when it arrives
and the agent handles it. Each agent ticks at its period on the wall clock
(without drift: the next tick is scheduled from the last one's due time,
not from when it ran). A liveliness token announces each agent. The peer
ends a second after it sees the game end (so its last messages get out),
on a stop from the launcher, on SIGINT/SIGTERM, or once the ground station
has been gone for longer than the lease (a player's peer has nobody to play
for), and closes its session in every case.

A ground station that started on provisional sets (``cast.AwaitedSets``)
looks in the cache for its own once a second, off the loop, and hands
them to its agents on the loop once they are there, noting both in its
log (``sets`` lines).

A run with a fault plan announces each fault as it begins on the game's
fault key; the peer applies what concerns it (``fault_effects``): its
shim cuts or degrades links (on the shim only: on a kernel network the
hub drops the packets), its agents' clock jumps or drifts, its phone's
GPS lies, and a peer a person started kills, stops or pauses itself, as
the launcher holds no process of it to signal. Only the launcher
announces faults.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import dataclasses
import functools
import logging
import os
import signal
import threading
import time
import typing
from collections.abc import Callable
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bearcat.agents.ground_station.ctf_cache import cached
from bearcat.agents.ground_station.event_log import EventLog
from bearcat.agents.human.agent import HumanAgent
from bearcat.agents.human.behaviour import TAKES_KEYS, TakesKeys
from bearcat.bus import keys
from bearcat.bus.clock import WallClock
from bearcat.bus.codec import Inbox
from bearcat.bus.errors import BusError
from bearcat.bus.handoff import Handoff
from bearcat.bus.messages import Control, FaultNotice, GameState
from bearcat.netem.shim import Shim
from bearcat.runtime.dispatch import Dispatcher
from bearcat.runtime.hand_in import serve_log
from bearcat.runtime.peer_spec import PeerSpec
from bearcat.scenarios.fault_effects import NETWORK_KINDS, apply_network, lie, skewed
from bearcat.scenarios.faults import BY_ITSELF, GROUND, GROUND_AGENTS, LAUNCHER, Clock, Gps
from bearcat.scenarios.schema import ScenarioError
from bearcat.solvers.ctf.queries import CtfQueries

if TYPE_CHECKING:
    from bearcat.runtime.world import World

log = logging.getLogger(__name__)

LINGER = 1.0  # s a peer stays up after the game ended
POLL = 0.1
AWAIT_POLL = 1.0  # s between looks in the cache for the sets a ground station awaits
SHUTDOWN_WAIT = 2.0  # s a UAV peer waits, on its way out, for a vehicle that does not answer
LAUNCHER_DIED = "the launcher died, and the peer with it (bearcat run --resume RUN takes the run up again)"
BODILESS = ("guidance",)
"""Kinds of key whose messages a peer's own log records without their body
when the run directory has the launcher's run-wide log (``events.jsonl``):
the launcher, on the ground station's side of every cut, logs every
guidance in full, so the ground station's log only says it sent each."""


async def run_peer(agents, session, game: str, *, awaited=None, adopt=None, say=None, warm_up=None, **setting) -> str:
    """Drive ``agents`` on ``session`` until the game ends; why it stopped,
    and how often each agent failed if any did. The session is closed on the
    way out, while the loop still stands, so no late sample is handed to it.
    ``setting`` is the peer's (``PeerRun``: its shim, record, fault plan,
    network and lease). ``awaited`` (``cast.AwaitedSets``) are the sets to
    hand to ``adopt`` once they are in the cache, which ``say`` is told of;
    ``warm_up()`` (``Cast.warm_up``) is run off the event loop before the
    peer says it is up, so that the game starts with the guidance ready."""
    return await PeerRun(agents, session, game, **setting).run(awaited=awaited, adopt=adopt, say=say, warm_up=warm_up)


class PeerRun:
    """One peer's agents on its ``session``, on the wall clock and the
    running event loop, writing to ``record``: what it hears goes through
    the ``shim`` (if the peer emulates its network) to the agents'
    handlers, fault notices of the plan ``faults`` are applied where they
    fall on this peer (``network``: where it runs), and a player's peer
    stops when the ground station has been gone for ``lease`` seconds."""

    def __init__(
        self,
        agents,
        session,
        game: str,
        *,
        shim: Shim | None = None,
        record: EventLog | None = None,
        faults: tuple = (),
        network: str = "shim",
        lease: float | None = None,
    ) -> None:
        self.agents, self.session, self.game = list(agents), session, game
        self.shim, self.faults, self.network, self.lease = shim, faults, network, lease
        self.loop = asyncio.get_running_loop()
        self.clock = WallClock()
        self.record = record or EventLog(None)
        self.dispatch = Dispatcher(self.record, self.clock.now)
        self.finished = asyncio.Event()
        self.why = "stopped"
        self.soon = Handoff(self.loop).put  # from Zenoh's threads; what arrives while the peer shuts down is dropped
        session.on_refused = lambda *refusal: self.soon(self._refused, *refusal)
        self.handles: dict[str, Callable] = {}
        self.held: list[tuple[Callable, tuple]] | None = None  # what arrived while the guidance warms up
        for agent in self.agents:
            self._attach(agent)
        self.notices = Inbox(session.name)
        if faults:
            session.subscribe(keys.fault(game), lambda k, p, s: self.soon(self._on_notice, k, p, s))
        self.orphaned: dict[str, asyncio.TimerHandle] = {}
        if lease is not None and all(agent.role in ("walker", "phone") for agent in self.agents):
            session.subscribe_liveliness(
                keys.alive(game, "ground-station", GROUND), lambda k, alive: self.soon(self._ground, k, alive)
            )
        self.parent = os.getppid()  # a SIGTERM once it has changed is the launcher's death (``peers``)
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                self.loop.add_signal_handler(sig, self._interrupted)
            except (NotImplementedError, RuntimeError):  # not the main thread
                pass

    async def run(self, *, awaited=None, adopt=None, say=None, warm_up=None) -> str:
        """Ready the guidance (``warm_up``), say the agents are up, tick them
        until the game ends, taking up the ``awaited`` sets on the way; why
        it stopped (see ``run_peer``)."""
        if warm_up is not None:
            await self._warm(warm_up)  # before the tokens: the launcher starts the game once every peer is up
        for agent in self.agents:
            self.session.declare_token(keys.alive(self.game, agent.role, agent.name))
        tasks = [asyncio.create_task(self._ticker(a)) for a in self.agents]
        if awaited is not None:
            tasks.append(asyncio.create_task(self._take_up(awaited, adopt, say)))
        if self.shim is not None and (self.shim.dead_zones is not None or self.faults):
            tasks.append(asyncio.create_task(self._poller(self.shim)))
        try:
            await self.finished.wait()
        finally:
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self.session.close()
            self.record.close()
        if self.dispatch.failures:
            counts = ", ".join(f"{name} {n}" for name, n in sorted(self.dispatch.failures.items()))
            return f"{self.why}; agent failures: {counts}"
        return self.why

    def _attach(self, agent) -> None:
        """Subscribe ``agent`` to what it hears, through the shim, and to what it watches."""
        self.dispatch.attach(agent, self.session)
        self.handles[agent.name] = functools.partial(self._handle, agent)
        arrived = functools.partial(self._arrived, agent)
        for expr in agent.subscriptions:
            self.session.subscribe(expr, lambda k, p, s: self.soon(arrived, k, p, s))
        for expr in agent.watches:
            self.session.subscribe_liveliness(expr, lambda k, alive, a=agent: self.soon(self._watched, a, k, alive))

    def _handle(self, agent, key, payload, sender) -> None:
        if self.session.closed:  # held by the shim past the end of the peer
            return
        if self.held is not None:
            self.held.append((self._handle, (agent, key, payload, sender)))
            return
        message = self.dispatch.receive(agent, key, payload, sender)
        if isinstance(message, GameState) and message.phase == "ended" and not self.finished.is_set():
            self.why = f"game ended: {message.reason}"
            self.loop.call_later(LINGER, self.finished.set)
        if isinstance(message, Control) and message.command == "start" and self.shim is not None:
            self.shim.epoch = message.t  # outage windows count from the start, on the launcher's clock
        if isinstance(message, Control) and message.command == "stop":
            self.why = f"stopped by the launcher: {message.reason}"
            self.loop.call_later(LINGER, self.finished.set)

    def _arrived(self, agent, key, payload, sender) -> None:
        now = self.clock.now()
        if self.shim is None:
            self._handle(agent, key, payload, sender)
            return
        for d in self.shim.transmit(sender, agent.name, key, payload, now, token=(agent.name, key, sender)):
            self.loop.call_later(max(d.at - now, 0.0), self._handle, agent, key, d.payload, sender)

    def _watched(self, agent, key, alive) -> None:
        if self.held is not None:
            self.held.append((self._watched, (agent, key, alive)))
        elif not self.session.closed:  # tokens vanish as the peer's own session closes
            self.dispatch.peer(agent, key, alive)

    def _refused(self, key, claimed, category, reason) -> None:
        self.dispatch.unbelieved(self.session.name, key, claimed, f"{category}: {reason}")

    def _on_notice(self, key, payload, sender) -> None:
        """Apply the fault a launcher's notice names where it falls on this peer."""
        notice = self.notices.accept(key, payload)
        if not isinstance(notice, FaultNotice) or sender != LAUNCHER or notice.fault >= len(self.faults):
            log.warning("a fault notice from %r was refused", sender)
            return
        fault, now, loop = self.faults[notice.fault], self.clock.now(), self.loop
        if fault.kind in NETWORK_KINDS and self.network == "shim" and self.shim is not None:
            apply_network(fault, self.shim, notice.start, notice.end, lambda peer: [peer])
        elif isinstance(fault, Clock) and fault.target == self.session.name:
            for agent in self.agents:
                self.dispatch.clocks[agent.name] = skewed(fault, notice.start)
            if notice.end is not None:
                loop.call_later(notice.end - now, lambda: [self.dispatch.clocks.pop(a.name, None) for a in self.agents])
        elif fault.kind in BY_ITSELF and fault.target == self.session.name:
            self._by_itself(notice.fault, fault)
        elif isinstance(fault, Gps):
            for agent in self.agents:
                if agent.name == fault.target and hasattr(agent, "phone"):  # a real phone's GPS is its own
                    agent.phone.lie = lie(fault)
                    if notice.end is not None:
                        loop.call_later(notice.end - now, setattr, agent.phone, "lie", None)

    def _by_itself(self, k: int, fault) -> None:
        """A process fault on this peer, which a person started, so no
        launcher holds its process to signal. A kill is a real SIGKILL, with
        no goodbye; a stop ends the peer cleanly, as SIGTERM would. A pause
        freezes the event loop, so nothing ticks and what arrives waits, as
        SIGSTOP would; its session's threads run on, so where the router
        would drop a frozen process's session, at the lease, the peer
        withdraws its tokens instead, and the terminal it runs in stays the
        person's."""
        said = f"fault[{k}] ({fault.describe()})"
        self.record.note(self.clock.now(), "fault-applied", fault=k, kind=fault.kind)
        if fault.kind == "kill":
            print(f"peer {self.session.name}: killed by {said}", flush=True)
            os.kill(os.getpid(), signal.SIGKILL)
        elif fault.kind == "stop":
            self.why = f"stopped by {said}"
            self.finished.set()
        else:
            held = fault.duration if self.lease is None else min(self.lease, fault.duration)
            time.sleep(held)
            tokens = [keys.alive(self.game, a.role, a.name) for a in self.agents] if held < fault.duration else []
            for key in tokens:
                self.session.withdraw_token(key)
            time.sleep(fault.duration - held)
            for key in tokens:
                self.session.declare_token(key)

    def _ground(self, key, alive) -> None:
        """The ground station's token came or went: a player's peer waits a lease for it, then stops."""
        if alive:
            for timer in self.orphaned.values():
                timer.cancel()
            self.orphaned.clear()
        elif not self.orphaned and not self.finished.is_set():
            assert self.lease is not None  # it is watched only with a lease
            self.orphaned["timer"] = self.loop.call_later(self.lease, self._give_up)

    def _give_up(self) -> None:
        self.why = f"the ground station has been gone for {self.lease:g} s"
        self.finished.set()

    def _interrupted(self) -> None:
        if _orphaned(self.parent):
            # The router died with the launcher: there is nobody left to say
            # goodbye to, and a session closing over a network that died too
            # (a kernel network's hub) would wait out Zenoh's close timeout.
            # Every line of the event log is written already.
            self.record.note(time.time(), "launcher-died")
            print(f"peer {self.session.name}: {LAUNCHER_DIED}", flush=True)
            os._exit(0)
        self.why = "interrupted"
        self.finished.set()

    async def _ticker(self, agent) -> None:
        self.dispatch.start(agent)
        due = self.loop.time()
        while True:
            due += agent.period
            await asyncio.sleep(max(due - self.loop.time(), 0.0))
            self.dispatch.tick(agent)

    async def _poller(self, shim: Shim) -> None:
        """Releases what the dead zones and the faults held, as they let it go."""
        while True:
            await asyncio.sleep(POLL)
            now = self.clock.now()
            for token, d in shim.poll(now):
                receiver, key, sender = typing.cast(tuple[str, str, str], token)  # as _arrived gave it
                self.loop.call_later(max(d.at - now, 0.0), self.handles[receiver], key, d.payload, sender)

    async def _take_up(self, awaited, adopt, say) -> None:
        """Look for the awaited sets until they are there, then answer from them."""
        grid = awaited.game.grid_points
        self.record.note(self.clock.now(), "sets", grid=awaited.provisional, awaited=grid)
        try:
            while (found := await self.loop.run_in_executor(None, cached, awaited.game, awaited.stages)) is None:
                await asyncio.sleep(AWAIT_POLL)
            adopt(CtfQueries(found.solution))
        except Exception as exc:  # the game goes on, on the provisional sets
            log.warning("the %d-point sets were not taken up (%s); guidance stays on provisional sets", grid, exc)
            return
        self.record.note(self.clock.now(), "sets", grid=grid, awaited=None)
        if say is not None:
            say(f"guidance answers from the {grid}-point sets from now on")

    async def _warm(self, warm_up) -> None:
        """Run ``warm_up`` off the loop, which stays free to hear a stop,
        while what arrives for the agents waits for it: the warm-up calls
        the agents' guidance itself, which is no code to call from two
        threads at once, and it holds the interpreter for long stretches
        as it loads or compiles code, which a call on the loop meanwhile
        would wait out on the clock its guard holds to its budget. What
        waited is then handled in the order it came."""
        began = self.clock.now()
        self.held = []
        try:
            await self.loop.run_in_executor(None, warm_up)
        except Exception as exc:  # the game's own first queries will show what is wrong
            log.warning("the guidance could not be readied before the game (%s)", exc)
        else:
            done = self.clock.now()
            self.record.note(done, "warmed", seconds=round(done - began, 3))
        finally:
            held, self.held = self.held, None
            for handle, args in held:
                handle(*args)


def _orphaned(parent: int) -> bool:
    """Whether process ``parent``, which started this one, has died. A parent
    killed with SIGKILL signals its children as its first thread exits, which
    hands them to a thread of its own still exiting: this process's parent
    is then the same number, but a zombie."""
    if os.getppid() != parent:
        return True
    try:
        text = Path(f"/proc/{parent}/stat").read_text()
    except OSError:
        return True
    return text[text.rindex(")") + 2 :].split()[0] in ("Z", "X")


def _run_wide(out) -> Path | None:
    """The launcher's run-wide event log in run directory ``out``, if it has one."""
    path = None if out is None else Path(out) / "events.jsonl"
    return path if path is not None and path.exists() else None


def start_peer(spec: PeerSpec, scenario, *, say=None, page=None) -> str:
    """Build the agents of peer ``spec`` in ``scenario`` and run them until
    the game ends (``bearcat peer``). With ``spec.certs``, a directory
    holding this peer's certificate and key, it seals what it sends and
    takes only what the access policy lets each provable sender publish;
    without, it believes every name (a private host). A ``secure`` peer is a
    client of a router over ``tls/`` alone, presenting that certificate. A
    "phone" peer is a person's real phone: it serves the page (``page``, a
    ``PageServer``; default: the spec's), tells ``say`` where, and joins the
    game once the page has sent its first fix. A peer
    restarted mid-game ``resume``s from its own log in ``out``.
    With ``transport`` "udp" its best-effort messages go to the same
    endpoints over ``udp/`` (see ``bus.zenoh_session``). On a ``network``
    "kernel" the links are impaired below it, so its shim keeps only the
    dead zones; GPS and compass error stay in the phone either way.
    A UAV peer flies the vehicle at MAVLink URL ``vehicle``; an ``emulated``
    vehicle's telemetry is the truth. A ``provisional`` ground station whose
    sets are not cached answers from coarser ones and takes its own up once
    they are (``bearcat run`` solves them meanwhile)."""
    from bearcat.bus.identity import Credentials
    from bearcat.bus.zenoh_session import ZenohSession, best_effort_endpoint, config
    from bearcat.netem.models import LinkModel
    from bearcat.runtime.world import world_of
    from bearcat.scenarios.faults import load_faults

    plan = None if spec.faults is None else load_faults(Path(spec.faults), scenario)
    world = world_of(scenario, seed=spec.seed, netem=spec.netem, transport=spec.transport, plan=plan)
    transport, plan = world.transport, world.plan
    out = spec.out
    lease_ms = round(1000 * scenario.lease)
    builder = _BUILDERS.get(spec.role)
    if builder is None:
        raise BusError(f"role {spec.role!r} cannot be started as a peer; start ground-station, walker, phone or uav")
    cast = builder(spec, world)
    agents, name, players = cast.agents, spec.name, cast.players
    if spec.resume and out is not None:
        from bearcat.runtime.recovery import last_sent
        from bearcat.runtime.recovery import resume as take_up

        last = last_sent(f"{out}/peers/{name}.jsonl")
        run_wide = _run_wide(out)
        if run_wide is not None:  # what the peer's own log left to the launcher's
            last = last_sent(run_wide, sender=name, kinds=BODILESS) | last
        for agent in agents:
            take_up(agent, last, scenario.name)
    positions: dict[str, tuple[float, float]] = {}
    credentials = None if spec.certs is None else Credentials(Path(spec.certs), name)
    connect, listen, mode = list(spec.connect), None if spec.listen is None else list(spec.listen), spec.mode
    if spec.secure:
        _check_secure(credentials, connect)
        mode, listen = "client", []  # a peer that listens could be reached around the router's access control
    if mode == "client" and listen is None:
        listen = []  # a client does not listen

    def joining():
        tls = credentials if spec.secure else None
        return config(listen=listen, connect=connect, mode=mode, lease_ms=lease_ms, tls=tls)

    with (
        closing(
            EventLog(
                None if out is None else f"{out}/peers/{name}.jsonl",
                append=True,
                bodiless=BODILESS if _run_wide(out) else (),
            )
        ) as record,
        ZenohSession(
            name,
            joining(),
            best_effort=None
            if transport == "tcp"
            else config(
                listen=[], connect=[best_effort_endpoint(e) for e in connect], mode="client", lease_ms=lease_ms
            ),
            credentials=credentials,
        ) as session,
    ):
        if spec.role == "ground-station":
            # A peer started elsewhere (a phone's bridge, a drone's companion) fetches these.
            from bearcat.maps.geojson import dumps

            geojson = dumps(scenario.map, units="metres").encode()
            session.serve(keys.map_query(scenario.name), lambda: geojson)
            session.serve(keys.scenario_query(scenario.name), lambda: scenario.text.encode())
            plan_text = b"" if spec.faults is None else Path(spec.faults).read_bytes()
            session.serve(keys.plan_query(scenario.name), lambda: plan_text)
        if world.zones is not None:
            # Dead zones need the position of each end of a link, which in
            # simulation the truth tells: a player's peer needs only its own
            # (the ground station's end stands still), the ground station every one.
            def on_truth(key, payload, sender):
                message = Inbox(name).accept(key, payload)
                if message is not None:
                    positions[message.agent] = scenario.map.to_local(message.lat, message.lon)

            every = spec.role == "ground-station"
            session.subscribe(
                keys.every(scenario.name, "truth") if every else keys.truth(scenario.name, name), on_truth
            )
        shim = world.shim(
            record.impaired,
            positions.get,
            (*GROUND_AGENTS, LAUNCHER),
            link=None if spec.network == "shim" else LinkModel(),
            epoch=None,
        )
        keyboard = [
            a for a in agents if isinstance(a, HumanAgent) and TAKES_KEYS in a.traits and a.behaviour is not None
        ]
        if keyboard:
            _read_keys(typing.cast(TakesKeys, keyboard[0].behaviour))
        peer = run_peer(
            agents,
            session,
            scenario.name,
            shim=shim,
            record=record,
            faults=plan,
            network=spec.network,
            lease=scenario.lease,
            awaited=None if players is None else players.awaited,
            adopt=None if players is None else players.adopt,
            say=say,
            warm_up=None if players is None else players.warm_up,
        )
        if spec.role == "phone":
            if page is None:
                from bearcat.agents.human.browser_bridge import page_server

                page = page_server(spec.page, spec.cert, spec.key, spec.token_file)
            reason = asyncio.run(_bridged(agents[0], page, peer, record, say or log.warning))
        elif cast.autopilot is None:
            reason = asyncio.run(peer)
        else:
            with asyncio.Runner() as runner:
                # MAVSDK's commands block a thread until the vehicle answers; one
                # that never will (its vehicle died) must not keep the peer alive.
                runner.get_loop().set_default_executor(DaemonExecutor())
                reason = runner.run(_fly(cast.autopilot, peer))
    if spec.hand_in and record.path is not None:
        with ZenohSession(name, joining(), credentials=credentials) as session:
            handed = serve_log(session, scenario.name, name, record.path, scenario.lease)
        kept = f"its log is kept at {record.path}"
        reason += f"; {kept}, and was handed to the launcher" if handed else f"; no launcher asked for its log: {kept}"
    return reason


@dataclass(frozen=True)
class _Cast:
    """What a role's builder gives its peer: the agents it runs, the cast
    they came from (None for a phone) and the UAV's autopilot, if any."""

    agents: list
    players: Any = None
    autopilot: Any = None


def _known(scenario, agent: str, ids, what: str) -> None:
    if agent not in ids:
        raise ScenarioError(
            f"{scenario.source}: there is no {what} {agent!r}; the {what}s are {', '.join(ids) or 'none'}"
        )


def _ground_station(spec: PeerSpec, world: World) -> _Cast:
    players = world.cast(
        people=[], ground=True, judge=spec.judge, provisional=spec.provisional, clock=time.perf_counter
    )
    assert players.guidance is not None  # a cast with its ground station
    return _Cast(players.ground, players)


def _uav(spec: PeerSpec, world: World) -> _Cast:
    from bearcat.agents.uav.autopilot import MavsdkAutopilot

    _known(world.scenario, spec.id, [u.id for u in world.scenario.uavs], "UAV")
    if not spec.vehicle:
        raise BusError("a UAV peer needs --vehicle URL, the MAVLink address of its vehicle")
    autopilot = MavsdkAutopilot(spec.vehicle, sysid=spec.sysid)
    players = world.cast(
        people=[], uavs=[spec.id], ground=False, autopilots={spec.id: autopilot}, uav_truth=spec.emulated
    )
    return _Cast([players.uavs[spec.id]], players, autopilot)


def _phone(spec: PeerSpec, world: World) -> _Cast:
    from bearcat.agents.human.page_phone import PagePhone

    _known(world.scenario, spec.id, world.scenario.ids, "agent")
    return _Cast([PagePhone(world.scenario.name, spec.id, world.scenario.map)])


def _walker(spec: PeerSpec, world: World) -> _Cast:
    _known(world.scenario, spec.id, world.scenario.ids, "agent")
    players = world.cast(people=[spec.id], ground=False, clock=time.perf_counter)
    return _Cast([players.people[spec.id]], players)


_BUILDERS: dict[str, Callable[..., _Cast]] = {
    "ground-station": _ground_station,
    "uav": _uav,
    "phone": _phone,
    "walker": _walker,
}


async def _bridged(phone, page, peer, record, say) -> str:
    """Serve ``phone``'s page, then play once the page has sent a fix; stop serving in every case."""
    from bearcat.agents.human.browser_bridge import Bridge
    from bearcat.bus.errors import BusError

    def dropped(reason: str) -> None:
        n = sum(phone.drops.values())
        if n == 1 or n % 100 == 0:
            log.warning("phone %s dropped a fix from its page (%d so far): %s", phone.name, n, reason)
        record.refused(time.time(), phone.name, phone.name, keys.fix(phone.game, phone.name), reason)

    bridge = Bridge(phone, page, time.time, on_drop=dropped)
    playing = False
    try:
        try:
            await bridge.start()
        except OSError as exc:
            raise BusError(
                f"phone {phone.name}: its page cannot be served at {page.host}:{page.port}: {exc.strerror or exc}"
            ) from None
        say(f"phone {phone.name}: open {page.url()} on the phone; the game waits for its first fix")
        await bridge.first_fix.wait()
        playing = True
        return await peer
    finally:
        if not playing:
            peer.close()
        await bridge.close()


def _check_secure(credentials, connect) -> None:
    """A sentence for a secure peer that could not be one."""
    from bearcat.bus.errors import BusError

    if credentials is None:
        raise BusError("a --secure peer needs --certs DIR, the directory holding its certificate and key")
    plain = [endpoint for endpoint in connect if not endpoint.startswith("tls/")]
    if not connect or plain:
        raise BusError(f"a --secure peer connects to a router over tls/ only, not {', '.join(plain) or 'nothing'}")


class DaemonExecutor(concurrent.futures.ThreadPoolExecutor):
    """Runs each call on a daemon thread of its own and, shutting down,
    waits for them a moment (``SHUTDOWN_WAIT``) and no longer: a call stuck
    in a library waiting for a vehicle that is gone is left behind, and dies
    with the process."""

    def __init__(self) -> None:
        super().__init__(max_workers=1)  # asyncio takes no other kind; none of its workers ever starts
        self._daemons: list[threading.Thread] = []

    def submit(self, fn, /, *args, **kwargs):
        future = concurrent.futures.Future()

        def run():
            if not future.set_running_or_notify_cancel():
                return
            try:
                future.set_result(fn(*args, **kwargs))
            except BaseException as exc:
                future.set_exception(exc)

        thread = threading.Thread(target=run, daemon=True, name="mavsdk-call")
        self._daemons = [t for t in self._daemons if t.is_alive()] + [thread]
        thread.start()
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        if wait:
            end = time.monotonic() + SHUTDOWN_WAIT
            for thread in self._daemons:
                thread.join(timeout=max(end - time.monotonic(), 0.0))


async def _fly(autopilot, peer) -> str:
    """Connect to the vehicle, then play; let go of it in every case."""
    try:
        await autopilot.connect()
    except BaseException:
        peer.close()  # the peer never started
        raise
    try:
        return await peer
    finally:
        await autopilot.close()


def fetch_scenario(
    game: str, connect, timeout: float = 10.0, *, certs=None, name: str | None = None, secure: bool = False
):
    """The scenario, map and fault plan the ground station of ``game``
    serves (``bearcat peer --scenario zenoh:GAME``); with ``certs``, asked
    as peer ``name`` and taken only from a provable ground station (over
    ``tls/`` when ``secure``). The run's plan, which the peer applies where
    it falls on it, replaces any the scenario's text holds."""
    import time

    from bearcat.bus.errors import BusError
    from bearcat.bus.identity import Credentials
    from bearcat.bus.zenoh_session import ZenohSession, config
    from bearcat.maps.geojson import parse_geojson
    from bearcat.scenarios.faults import parse_plan
    from bearcat.scenarios.schema import parse_scenario

    if certs is not None and name is None:
        raise BusError("asking with certificates needs the peer name to ask as")
    credentials = None if certs is None or name is None else Credentials(certs, name)
    asker = f"fetch-{int(time.time() * 1000) % 10**9}" if credentials is None else credentials.name
    if secure:
        _check_secure(credentials, connect)
    how = config(connect=connect, listen=[], mode="client", tls=credentials) if secure else config(connect=connect)
    with ZenohSession(asker, how, credentials=credentials) as session:
        end = time.monotonic() + timeout
        text = geojson = plan = None
        while time.monotonic() < end and (text is None or geojson is None or plan is None):
            text = text or session.fetch(keys.scenario_query(game), timeout=1.0)
            geojson = geojson or session.fetch(keys.map_query(game), timeout=1.0)
            plan = plan if plan is not None else session.fetch(keys.plan_query(game), timeout=1.0)
    if text is None or geojson is None or plan is None:
        raise BusError(
            f"no ground station of game {game!r} answered at {', '.join(connect) or 'the default endpoints'}"
        )
    game_map = parse_geojson(geojson.decode(), source=f"the map of game {game}", default_name=game)
    scenario = parse_scenario(text.decode(), source=f"the scenario of game {game}", game_map=game_map)
    faults = parse_plan(plan.decode(), scenario, source=f"the fault plan of game {game}")
    return dataclasses.replace(scenario, faults=faults)


def _read_keys(behaviour: TakesKeys) -> None:
    """Feed arrow keys and WASD from this terminal to a behaviour that takes keys, on a thread;
    a key it fails on is logged and the next is read."""
    import sys
    import termios
    import threading
    import tty

    if not sys.stdin.isatty():
        raise ScenarioError("the keyboard behaviour needs a terminal: start this peer from one")
    arrows = {"A": "up", "B": "down", "C": "right", "D": "left"}
    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)

    def read():
        tty.setcbreak(fd)
        try:
            while True:
                ch = sys.stdin.read(1)
                if ch == "\x1b" and sys.stdin.read(1) == "[":
                    ch = arrows.get(sys.stdin.read(1), "")
                elif ch == " ":
                    ch = "space"
                if ch in ("q", "\x03", ""):
                    break
                try:
                    behaviour.press(ch.lower())
                except Exception:
                    log.exception("the behaviour failed on key %r; reading on", ch)
        finally:
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)

    threading.Thread(target=read, daemon=True, name="keys").start()
