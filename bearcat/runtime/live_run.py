"""One live run, from its router being up to its outcome.

``launch`` checks the request, solves what the ground station needs, opens
the router and the run's record, and hands them to a ``LiveRun``, whose
steps are methods that can be followed, and tested, one at a time:

- ``start``: the peers the launcher starts itself (the ground station, a
  walker per agent, a page server per phone, a UAV peer and its vehicle
  emulator per UAV), and the command for each peer a person starts;
- ``await_up``: every peer's liveliness token, and who joined from other
  machines as they come;
- ``begin``: the fault plan's injector and the start command;
- ``supervise``: until the referee ends the game, or a peer's death, the
  time limit or Ctrl-C ends the run;
- ``stop``: the stop command, then SIGTERM, then SIGKILL, and the outcome,
  written beside what the run recorded if the disk lets it.

Everything the launcher's session hears of the game is recorded as it
comes, from the moment the run exists: what a sender sent (within its
budget), what was refused and why, and whose tokens came and went.

Ctrl-C and SIGTERM, while a run plays, only set a flag that the waiting
steps look at between their polls. An exception raised by a signal
wherever the launcher happens to be (Python's KeyboardInterrupt) can land
inside a lock's bookkeeping, a thread's start or a process's spawn and
leave them half done; a flag ends the run at a known point, with every
step after it free to stop the peers and keep the outcome.
"""

from __future__ import annotations

import json
import logging
import signal
import socket
import subprocess
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import msgspec

from bearcat.agents.ground_station.event_log import EventLog, read_events
from bearcat.agents.human.behaviour import TAKES_KEYS
from bearcat.bus import keys
from bearcat.bus.addresses import reachable
from bearcat.bus.budget import SenderBudget
from bearcat.bus.codec import Inbox, encode
from bearcat.bus.endpoints import WILDCARDS, Endpoint
from bearcat.bus.messages import Control, GameState
from bearcat.bus.zenoh_session import ZenohSession
from bearcat.runtime import processes, remote
from bearcat.runtime.dispatch import FAILED
from bearcat.runtime.hand_in import take_log
from bearcat.runtime.live_faults import LiveFaults
from bearcat.runtime.peer_commands import BEARCAT, VEHICLE, free_port, started_by_hand, vehicle_command
from bearcat.runtime.peer_spec import PeerSpec, flags, write_spec
from bearcat.runtime.peers import LocalPeers
from bearcat.runtime.supervisor import Supervisor
from bearcat.scenarios.faults import GROUND, LAUNCHER
from bearcat.scenarios.schema import Scenario

log = logging.getLogger(__name__)

STARTUP = 60.0  # s for every peer to come up
GRACE = 5.0  # s past the time limit before the launcher stops a game itself
STOP_WAIT = 5.0  # s a peer gets to exit after the stop command, and again after SIGTERM
LOOK = 0.5  # s between looks at who joined the router from other machines
RESUMED_SEQ = 1_000_000  # the number of the control a run taken up again sends first: above any its first launcher sent


@dataclass
class LiveOutcome:
    scenario: str
    winner: str | None
    reason: str
    elapsed: float
    ended: bool
    peers: dict[str, int | None] = field(default_factory=dict)  # exit codes
    failures: dict[str, int] = field(default_factory=dict)  # agent -> exceptions it raised
    out: str = ""
    faults: list[dict] = field(default_factory=list)  # each fault applied: its index, kind, peers and time


@dataclass(frozen=True)
class RunSettings:
    """What a live run was asked for, checked (``launch.preflight``); see
    ``launch.launch`` for each. ``fill`` takes the small disk's last bytes
    when a fault fills it; ``plan`` is the fault plan."""

    scenario: Scenario
    scenario_ref: str
    out: Path
    plan: tuple
    seed: int
    netem: str
    transport: str
    say: Callable[[str], None]
    startup: float = STARTUP
    fill: Callable[[], object] | None = None
    secure: bool = False
    phones: tuple[str, ...] = ()
    joins: tuple[str, ...] = ()
    page: tuple[str, int] = ("0.0.0.0", 8443)
    provisional: bool = False
    listen: tuple[Endpoint, ...] = ()
    resumed: bool = False  # the run is taken up again after its launcher died (``runtime.resume``)


class LiveRun:
    """One run's peers, its router's ``session`` and its ``record``, with the
    peers started from ``places`` with the certificates in ``certs``;
    ``elsewhere`` the endpoints where peers on other machines join."""

    def __init__(
        self,
        settings: RunSettings,
        places: LocalPeers,
        session: ZenohSession,
        record: EventLog,
        certs: Path,
        elsewhere: list[str],
    ) -> None:
        self.settings = settings
        self.places = places
        self.session = session
        self.record = record
        self.certs = certs
        self.elsewhere = elsewhere
        scenario = settings.scenario
        self.game = scenario.name
        self.by_hand = started_by_hand(scenario, settings.joins)
        self.expected = {keys.alive(self.game, "referee", "referee"), keys.alive(self.game, "ground-station", GROUND)}
        self.expected |= {
            keys.alive(self.game, "phone" if a.id in settings.phones else "walker", a.id) for a in scenario.agents
        }
        self.expected |= {keys.alive(self.game, "uav", u.id) for u in scenario.uavs}
        if scenario.uavs:
            self.expected.add(keys.alive(self.game, "ground-station", "uav-tasking"))
        self.children: dict[str, subprocess.Popen] = {}
        self.how: dict[str, tuple] = {}  # peer -> (role, flags): how to start it again
        self.injector: LiveFaults | None = None
        self.started_at: float | None = None
        self.supervisor = Supervisor(scenario.supervision)
        self._mourned: set[str] = set()  # peers whose death is recorded and who have not started again
        self._due: dict[str, float] = {}  # peer -> when (monotonic) it starts again
        self._inbox = Inbox(LAUNCHER)
        self._budget = SenderBudget()
        self._final: dict = {}
        self._alive: set[str] = set()
        self._ever_alive: set[str] = set()
        self._lock = threading.Lock()
        self._interrupted = threading.Event()
        self._heard: tuple[str, float] | None = None  # the signal that ended the run, and when
        session.on_refused = self._forged
        session.subscribe(keys.game_wide(self.game), self._seen)
        session.subscribe_liveliness(keys.every(self.game, "alive"), self._liveliness)

    def play(self) -> LiveOutcome:
        """Every step in turn; the peers are stopped and the outcome kept however the run ends."""
        reason = None
        with self._signals_end_the_run():
            try:
                self.start()
                reason = self._unless_interrupted(self.await_up)
                if reason is None:
                    self.begin()
                    reason = self._unless_interrupted(self.supervise)
            finally:
                outcome = self.stop(reason)
        return outcome

    @contextmanager
    def _signals_end_the_run(self) -> Iterator[None]:
        """Ctrl-C and SIGTERM set the run's flag while it plays (in the main
        thread only, where Python lets a handler be set)."""

        def heard(number, _frame) -> None:
            if self._heard is None:
                self._heard = (signal.Signals(number).name, time.time())
            self._interrupted.set()

        try:
            kept = {number: signal.signal(number, heard) for number in (signal.SIGINT, signal.SIGTERM)}
        except ValueError:  # not the main thread
            kept = {}
        try:
            yield
        finally:
            for number, handler in kept.items():
                signal.signal(number, handler)

    def _unless_interrupted(self, step: Callable[[], str | None]) -> str | None:
        """Why ``step`` ended the run, or "interrupted" if a signal did (noted
        with the signal and the moment it was heard)."""
        reason = step()
        if self._heard is None:
            return reason
        name, at = self._heard
        with self._lock:
            self.record.note(at, "interrupted", signal=name)
        return "interrupted"

    def _pause(self, seconds: float) -> bool:
        """Wait ``seconds``, or less if a signal comes; whether one came."""
        return self._interrupted.wait(seconds)

    # What the launcher's session hears, from the moment the run exists.

    def _within_budget(self, sender, key, now) -> bool:
        """Whether what ``sender`` put on ``key`` may cost the record a line (under the lock)."""
        if self._budget.allow(sender, key, now):
            return True
        for (who, where), n in self._budget.news(now).items():
            self.record.note(now, "over-budget", sender=who, receiver=LAUNCHER, key=where, dropped=n)
        return False

    def _seen(self, key, payload, sender) -> None:
        now = time.time()
        with self._lock:
            if not self._within_budget(sender, key, now):
                return
        message = self._inbox.accept(key, payload)
        with self._lock:
            if message is None:
                self.record.refused(now, sender, LAUNCHER, key, "undecodable or wrong for its key")
                return
            self.record.sent(now, sender, key, message)
            if isinstance(message, GameState) and message.phase == "ended" and "state" not in self._final:
                self._final["state"] = message
        if self.injector is not None:
            self.injector.saw(message, now)

    def _forged(self, key, claimed, category, reason) -> None:
        now = time.time()
        with self._lock:
            if self._within_budget(claimed, key, now):
                self.record.refused(now, claimed, LAUNCHER, key, f"{category}: {reason}")

    def _liveliness(self, key, up) -> None:
        with self._lock:
            (self._alive.add if up else self._alive.discard)(key)
            if up:
                self._ever_alive.add(key)
            self.record.note(time.time(), "alive" if up else "gone", key=key)

    def _ended(self) -> bool:
        with self._lock:
            return "state" in self._final

    # The steps.

    def start(self) -> None:
        """Start the peers that are the launcher's to start, and say how to start the others."""
        s = self.settings
        phones = s.phones
        self.how[GROUND] = (
            "ground-station",
            {"judge": "fixes" if phones else "truth", "provisional": s.provisional},
        )
        self.how |= {a.id: ("walker", {}) for a in s.scenario.agents if a.id not in self.by_hand and a.id not in phones}
        pages = _pages(tuple(p for p in phones if p not in self.by_hand), s.page, s.out)
        self.how |= {name: server_how for name, (_, server_how) in pages.items()}
        for name in list(self.how):
            self.children[name] = self.start_peer(name, again=s.resumed)
        link_host = link_host_of(s.page[0], s.listen) if pages else ""
        for name, (server, _) in pages.items():
            _say_link(name, server, self.children[name], s.say, link_host)
        for k, uav in enumerate(s.scenario.uavs):
            if uav.id not in self.by_hand:
                self._start_uav(k, uav.id)
        self._say_who_joins_by_hand()

    def spec(self, role: str, name: str, at: str, **own) -> PeerSpec:
        """Peer ``name``'s spec in ``role``, joining the router at ``at``, with the settings of its role ``own``."""
        s = self.settings
        faults = str((s.out / "faults.toml").resolve()) if s.plan else None
        return PeerSpec(
            role=role,  # type: ignore[arg-type]
            scenario=s.scenario_ref,
            id=name,
            connect=(at,),
            mode="client",
            seed=s.seed,
            netem=s.netem,
            network=self.places.impairs,  # type: ignore[arg-type]
            transport=s.transport,  # type: ignore[arg-type]
            out=str(s.out),
            certs=str(self.certs),
            secure=s.secure,
            faults=faults,
            **own,
        )

    def start_peer(self, name: str, *, again: bool = False) -> subprocess.Popen:
        """Start peer ``name`` as ``how`` says, from the spec it is handed in
        ``RUN/peers``; ``again`` resumes one a fault stopped."""
        s = self.settings
        role, own = self.how[name]
        path = s.out / "peers" / f"{name}{'.resumed' if again else ''}.spec.json"

        def command(at: str) -> list[str]:
            write_spec(path, self.spec(role, name, at, resume=again, **own))
            return [*BEARCAT, "peer", "--spec", str(path)]

        # The ground station and the phones' bridges stay on the laptop: a real phone's network is real.
        colocated = role in ("ground-station", "phone")
        log_path = s.out / "peers" / f"{name}.log"
        beside = self.children.get(f"vehicle-{name}") if role == "uav" else None
        peer = self.places.start(name, command, log_path, colocated=colocated, again=again, beside=beside)
        processes.record(s.out, name, peer.pid)
        return peer

    def _start_uav(self, k: int, name: str) -> None:
        """UAV ``k``'s peer, and the vehicle emulator it flies over MAVLink on a free UDP port."""
        s = self.settings
        port = free_port(socket.SOCK_DGRAM)
        self.how[name] = ("uav", {"vehicle": f"udpin://0.0.0.0:{port}", "sysid": k + 1, "emulated": True})
        flyer = self.children[name] = self.start_peer(name, again=s.resumed)
        vehicle = f"vehicle-{name}"
        self.children[vehicle] = self.places.start_vehicle(
            flyer, vehicle_command(s.scenario, k, port), s.out / "peers" / f"{vehicle}.log"
        )
        processes.record(s.out, vehicle, self.children[vehicle].pid)

    def _say_who_joins_by_hand(self) -> None:
        """The command for each peer a person starts. One started elsewhere
        fetches the scenario from the ground station, keeps its logs on its
        own machine and runs that machine's own installation."""
        s = self.settings
        program: tuple[str, ...]
        if self.elsewhere:
            at, program = self.elsewhere[0], ("bearcat",)
            if not self.by_hand:
                s.say("router: no agent or UAV is left for another machine to start; --joins AGENT leaves one")
        else:
            at, program = self.places.loopback, BEARCAT
        uavs = [u.id for u in s.scenario.uavs]
        for name in (p for p in (*s.scenario.ids, *uavs) if p in self.by_hand):
            role = "uav" if name in uavs else "walker"
            spec = self.spec(role, name, at, **({"vehicle": VEHICLE} if role == "uav" else {}))
            # Started by hand on the host's own network; it applies the plan's faults on itself (``PeerRun``).
            spec = msgspec.structs.replace(spec, network="shim")
            if self.elsewhere:  # the scenario, map and plan come from the ground station; the log comes back
                kept = f"runs/{s.out.name}"  # on that machine
                spec = msgspec.structs.replace(spec, scenario=f"zenoh:{self.game}", out=kept, faults=None, hand_in=True)
            bridge = [*program, "phone", "--connect", at, "--game", self.game, "--id", name, "--certs", str(self.certs)]
            bridge += [] if spec.out is None else ["--out", spec.out]
            bridge += ["--hand-in"] if spec.hand_in else []
            bridge += ["--secure"] if s.secure else []
            chosen = bridge if name in s.phones else [*program, "peer", *flags(spec)]
            s.say(
                _joining(
                    s.scenario,
                    name,
                    name in s.phones,
                    chosen,
                    certs=self.certs,
                    elsewhere=bool(self.elsewhere),
                )
            )

    def await_up(self) -> str | None:
        """Wait for every peer's token, saying who joined from other
        machines as they come; why the run cannot start, if it cannot."""
        s = self.settings
        patient = self.by_hand or s.phones  # a person has to start something: give them time
        deadline = time.monotonic() + (s.startup if not patient else 10 * s.startup)
        arrived: set[remote.Arrival] = set()
        look = time.monotonic()
        while True:
            with self._lock:
                missing = sorted(self.expected - self._alive)
            if (self.elsewhere or self.by_hand) and time.monotonic() >= look:
                look = time.monotonic() + LOOK
                for arrival in remote.arrivals(self.session.links(), arrived, frozenset(self.by_hand)):
                    s.say(f"{self.game}: {arrival.describe()}")
                    with self._lock:
                        self.record.note(time.time(), "joined", **vars(arrival))
            if not missing:
                return None
            dead = [n for n, p in self.children.items() if p.poll() is not None]
            if dead:
                return f"peer {dead[0]} exited with code {self.children[dead[0]].returncode} before the start"
            if time.monotonic() > deadline:
                return f"peers not up after {s.startup:g} s: {', '.join(k.rsplit('/', 1)[-1] for k in missing)}"
            if self._pause(0.05):
                return None

    def begin(self) -> None:
        """Arm the fault plan and send the start command; a run taken up again
        sends the resume command instead (a UAV whose emulated vehicle died
        with the launcher takes off again), and keeps its game clock."""
        s = self.settings
        if s.resumed:
            self._take_up()
            return
        if s.plan:
            self.injector = LiveFaults(
                s.plan,
                game=self.game,
                session=self.session,
                record=self.record,
                lock=self._lock,
                children=self.children,
                restart=lambda name: self.start_peer(name, again=True),
                network=getattr(self.places, "network", None),
                logs=s.out / "peers",
                fill=s.fill,
            )
        begin = Control(t=time.time(), command="start", seq=1)
        self.places.game_started(begin.t)
        self.session.put(keys.control(self.game), encode(begin))
        if self.injector is not None:
            self.injector.begin(begin.t)
        self.started_at = time.monotonic()
        s.say(f"{self.game}: {len(self.expected)} peers up; game started")

    def _take_up(self) -> None:
        s = self.settings
        if s.plan:
            s.say(f"{self.game}: the fault plan is not applied again: its faults before the gap stay recorded")
        t0 = _game_start(s.out / "events.jsonl")
        go = Control(t=time.time(), command="resume" if t0 is not None else "start", seq=RESUMED_SEQ)
        self.session.put(keys.control(self.game), encode(go))
        self.started_at = time.monotonic() - (0.0 if t0 is None else time.time() - t0)
        s.say(f"{self.game}: {len(self.expected)} peers up; game taken up again")

    def supervise(self) -> str | None:
        """Wait for the end of the game, starting again each peer that dies
        when no fault plan asked for it, as its role's policy says; why the
        launcher had to end the game, if it did (a dead walker's forfeit is
        the referee's to call, once its lease to rejoin has run out; a peer a
        fault restarts is not dead)."""
        s = self.settings
        assert self.started_at is not None, "supervise() follows begin()"
        limit = s.scenario.time_limit + GRACE
        logs = s.out / "peers"
        gone_since = None
        while True:
            if self._ended():
                return None
            if self.injector is not None:
                self.injector.respawn()
            downed = {} if self.injector is None else dict(self.injector.out_of_play)
            given_up = self._mourn(downed)
            if given_up is not None:
                return given_up
            dead = [
                n
                for n, p in self.children.items()
                if p.poll() is not None and n not in self._due and not downed.get(n, ("", False))[1]
            ]
            if dead:
                if GROUND in dead:
                    if GROUND in downed:
                        return f"the ground station is gone: {downed[GROUND][0]}"
                    return f"the ground station exited with code {self.children[GROUND].returncode}{_why(logs, GROUND)}"
                gone_since = gone_since or time.monotonic()
                if time.monotonic() - gone_since > s.scenario.lease + 3.0:
                    return f"peer {dead[0]} exited with code {self.children[dead[0]].returncode}{_why(logs, dead[0])}"
            if time.monotonic() - self.started_at > limit:
                return f"no result within {limit:g} s"
            if self._pause(0.05):
                return None

    def _mourn(self, downed: dict[str, tuple[str, bool]]) -> str | None:
        """Record each death no fault caused, and start the peer again when
        its backoff is over, if its policy says so; why the run gives up on
        a peer that died too often, if it does."""
        now = time.monotonic()
        for name, process in self.children.items():
            if process.poll() is None or name in downed or name in self._mourned:
                continue
            self._mourned.add(name)
            death = self.supervisor.died(name, self.how.get(name, (None,))[0], process.returncode, now)
            with self._lock:
                self.record.note(time.time(), "died", **vars(death))
            if death.gives_up:
                return death.why
            if death.restart:
                self._due[name] = now + death.wait
                _say_in_log(
                    self.settings.out / "peers" / f"{name}.log",
                    f"peer {name}: died with code {death.code}, which no fault plan asked for; "
                    f"started again in {death.wait:g} s ({death.why})",
                )
        for name, due in list(self._due.items()):
            if now >= due:
                del self._due[name]
                self._mourned.discard(name)
                self.children[name] = self.start_peer(name, again=True)
                with self._lock:
                    self.record.note(time.time(), "restarted", peer=name, pid=self.children[name].pid)
        return None

    def stop(self, reason: str | None) -> LiveOutcome:
        """Stop every peer the launcher started; the outcome, recorded and written."""
        s = self.settings
        if self.injector is not None:
            self.injector.close()
        codes = self._stop_all(reason)
        self._take_logs()
        state = self._final.get("state")
        outcome = LiveOutcome(
            scenario=self.game,
            winner=state.winner if state else None,
            reason=state.reason if state else (reason or "stopped"),
            elapsed=state.elapsed
            if state
            else (0.0 if self.started_at is None else time.monotonic() - self.started_at),
            ended=state is not None,
            peers=codes,
            failures=agent_failures(s.out / "peers"),
            out=str(s.out),
            faults=[] if self.injector is None else self.injector.applied,
        )
        self.record.note(time.time(), "outcome", **vars(outcome))
        _keep(s.out, outcome, self.record, s.say)
        return outcome

    def _take_logs(self) -> None:
        """Keep the log each peer started elsewhere hands in, with its seal;
        say where one that hands in none keeps it."""
        s = self.settings
        if not self.elsewhere:
            return
        came = {key.rsplit("/", 1)[-1] for key in self._ever_alive}
        for name in sorted(self.by_hand & came):
            seal = take_log(self.session, self.game, name, s.out, s.scenario.lease)
            with self._lock:
                if seal is None:
                    self.record.note(time.time(), "no-log", peer=name)
                else:
                    self.record.note(time.time(), "handed-in", **msgspec.structs.asdict(seal))
            if seal is None:
                s.say(f"{self.game}: {name} handed in no log within the lease; it keeps it on its own machine")

    def _stop_all(self, reason: str | None) -> dict[str, int | None]:
        """The stop command, then SIGTERM, then SIGKILL, each waited on; each peer's exit code."""
        children = self.children
        if not self._ended() and children:
            try:
                seq = RESUMED_SEQ + 1 if self.settings.resumed else 2
                stop = Control(t=time.time(), command="stop", reason=(reason or "")[:200], seq=seq)
                self.session.put(keys.control(self.game), encode(stop))
            except Exception:
                log.exception("could not send the stop command")
        for signal_name in ("wait", "terminate", "kill"):
            deadline = time.monotonic() + STOP_WAIT
            for p in children.values():
                if p.poll() is None and signal_name != "wait":
                    getattr(p, signal_name)()
            while time.monotonic() < deadline and any(p.poll() is None for p in children.values()):
                time.sleep(0.05)
            if all(p.poll() is not None for p in children.values()):
                break
        return {name: p.poll() for name, p in children.items()}


def link_host_of(host: str, listen: tuple[Endpoint, ...]) -> str:
    """The address a phone is told to open pages served at ``host`` at:
    ``host`` itself, unless it is every interface; then the one the router
    takes other machines at (the field's network), else what this
    machine's network says (``bus.addresses.reachable``)."""
    return remote.link_host(host, listen) or reachable(host)


def _joining(scenario: Scenario, name: str, phone: bool, command: list[str], *, certs: Path, elsewhere: bool) -> str:
    """What to tell the user who starts peer ``name`` by hand: the
    ``command`` that serves its phone's page, or that starts its walker or
    UAV, in a terminal here or on another machine (``elsewhere``, with its
    own copy of its certificate from ``certs``)."""
    notes = []
    if phone:
        what = f"agent {name} plays from a phone whose page you serve"
    elif name in [u.id for u in scenario.uavs]:
        what = f"UAV {name} flies from its own computer"
        notes.append(f"--vehicle: its autopilot's MAVLink URL, e.g. {VEHICLE} or serial:///dev/ttyACM0:57600")
    else:
        keyboard = scenario.behaviour_of(name).entry.has(TAKES_KEYS)
        what = f"agent {name} {'is driven from a keyboard' if keyboard else 'joins by hand'}"
    if elsewhere:
        notes.append(f"--certs: the directory on that machine holding ca.pem, {name}.pem and {name}.key from {certs}")
    where = "on its machine" if elsewhere else "in a terminal"
    return f"{what}; {where}, run:\n  " + " ".join(command) + "".join(f"\n  ({note})" for note in notes)


def _pages(phones: tuple[str, ...], page: tuple[str, int], out: Path) -> dict[str, tuple]:
    """For each of ``phones``, its page's server (on successive ports from
    ``page``, each with a token of its own, kept where only this user reads
    it) and how to start its peer."""
    from bearcat.agents.human.browser_bridge import PageServer, new_token

    pages = {}
    if phones:
        (out / "phones").mkdir(mode=0o700, exist_ok=True)
    for k, name in enumerate(phones):
        token_file = out / "phones" / f"{name}.token"
        kept = token_file.read_text().strip() if token_file.exists() else ""  # a run taken up again keeps its links
        server = PageServer(host=page[0], port=page[1] + k, token=kept or new_token())
        token_file.touch(mode=0o600)
        token_file.write_text(server.token + "\n")
        pages[name] = (server, ("phone", {"page": f"{server.host}:{server.port}", "token_file": str(token_file)}))
    return pages


def _say_link(name: str, server, peer: subprocess.Popen, say, host: str, wait: float = STARTUP) -> None:
    """Once ``peer`` serves its page, the link to open on the phone (naming ``host``) and its QR code."""
    address = "127.0.0.1" if server.host in WILDCARDS else server.host
    end = time.monotonic() + wait
    while time.monotonic() < end and peer.poll() is None:
        try:
            socket.create_connection((address, server.port), timeout=0.5).close()
            break
        except OSError:
            time.sleep(0.1)
    else:
        return  # the peer died or never served: the launcher says so in its own words
    say(f"agent {name} plays from a phone: open {server.url(host)} on it (the game waits for its first fix)")
    say(server.qr(host))


def _keep(out: Path, outcome: LiveOutcome, record: EventLog, say) -> None:
    """Write the outcome; a disk that refuses it gets it said instead, and so do the lines it refused."""
    text = json.dumps(vars(outcome), indent=2) + "\n"
    try:
        (out / "outcome.json").write_text(text)
    except OSError as exc:
        say(f"cannot write {out / 'outcome.json'} ({exc.strerror or exc}); the outcome:\n{text}")
    if record.lost:
        say(f"{out / 'events.jsonl'}: the disk refused {record.lost} line(s) ({record.failure})")


def _say_in_log(path: Path, line: str) -> None:
    """Append ``line`` to a peer's log, which the peer cannot write itself (it is dead)."""
    with open(path, "a", encoding="utf-8") as log_file:
        log_file.write(line + "\n")


def agent_failures(peers: Path) -> dict[str, int]:
    """How often each agent raised, from the ``failed`` events of the peers' logs in ``peers``."""
    counts: Counter[str] = Counter()
    for path in sorted(peers.glob("*.jsonl")):
        counts.update(e["agent"] for e in read_events(path) if e["event"] == FAILED)
    return dict(sorted(counts.items()))


def _game_start(events: Path) -> float | None:
    """When (Unix time) the game in a run's log started, by its referee's clock; None if it had not."""
    for e in read_events(events):
        message = e.get("message") if e["event"] == "sent" else None
        if isinstance(message, dict) and message.get("type") == "state" and message["phase"] != "waiting":
            return message["t"] - message["elapsed"]
    return None


def _why(logs: Path, name: str) -> str:
    """What a peer that exited said of why (``peer NAME: REASON``, its log's last words), as a clause."""
    try:
        lines = (logs / f"{name}.log").read_text(errors="replace").splitlines()
    except OSError:
        return ""
    said = next((line for line in reversed(lines) if line.startswith(f"peer {name}: ")), None)
    return "" if said is None else f" ({said.split(': ', 1)[1][:120]})"
