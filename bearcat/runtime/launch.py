"""Launching a live run: every peer its own process over Zenoh on this host.

The launcher solves what the ground station will need first (so no peer
starts against an empty cache): the scenario's sets, or provisional ones
a ``provisional`` ground station answers from until the scenario's, solved
behind the game, are in the cache. It listens on a free loopback port that every
peer connects to, starts the ground station and one walker per agent (and for each UAV a
``bearcat vehicle`` emulator on its own UDP port, PX4 SITL's 14540 + i
convention moved to free ports, with a UAV peer flying it), waits
until every peer's liveliness token is up, sends the start command and
supervises: the run ends when the referee says so, when a peer process dies
(the referee sees its token vanish and ends the game; the launcher ends the
run itself if the ground station is the one that died), at the time limit,
or on Ctrl-C. In every case the launcher then stops every peer it started
(a stop command, then SIGTERM, then SIGKILL) and leaves no process behind.
Agents driven from a keyboard, and the agents and UAVs a user names to
join by hand (``joins``: a walker started in another terminal, a phone's
page served by a ``bearcat phone`` of the user's own), are not started
here: the launcher prints the command to run, and waits. With ``listen``
the router also takes peers from other machines (``remote``): the
launcher says where they join, prints the command each runs there (which
fetches the scenario from the ground station), and, while it waits, who
joined from where.

The launcher's own session records every message of the game it sees into
``events.jsonl``; each peer writes what it sent and received, what its
network shim did to the messages it received and its agents' failures into
``peers/NAME.jsonl`` (the ground station's guidance without its body, which
``events.jsonl`` holds: ``live.BODILESS``), and its log into ``peers/NAME.log``. The outcome counts
the failures of each agent from those logs. Each process the launcher
starts is recorded in ``processes.jsonl`` as it starts (``processes``), so
the run checker knows which processes were the run's.

A fault plan is kept in the run directory (``faults.toml``), handed to every
peer, and applied by the launcher as the game goes (``live_faults``): a
peer a fault kills is the referee's to judge once its lease to rejoin runs
out, a restarted one is started again and resumes, and a ground station a
fault kills for good ends the run, naming the fault.
"""

from __future__ import annotations

import json
import logging
import socket
import subprocess
import sys
import threading
import time
from collections import Counter
from contextlib import closing, nullcontext
from dataclasses import dataclass, field
from pathlib import Path

from bearcat.agents.ground_station.event_log import EventLog, read_events
from bearcat.agents.ground_station.rerun_recording import finish_run
from bearcat.bus import keys
from bearcat.bus.access import access_control
from bearcat.bus.addresses import is_local, local_addresses, reachable
from bearcat.bus.budget import SenderBudget
from bearcat.bus.codec import Inbox, encode
from bearcat.bus.endpoints import WILDCARDS, Endpoint
from bearcat.bus.errors import BusError
from bearcat.bus.identity import Credentials, hosts_named
from bearcat.bus.messages import Control, GameState
from bearcat.bus.zenoh_session import ZenohSession, config
from bearcat.runtime import processes, remote
from bearcat.runtime.credentials import covering, members, run_authority
from bearcat.runtime.dispatch import FAILED
from bearcat.runtime.live_faults import LiveFaults
from bearcat.runtime.peers import KernelPeers, LocalPeers
from bearcat.runtime.run_directory import write_scenario
from bearcat.runtime.small_disk import SmallDisk
from bearcat.scenarios.faults import GROUND, LAUNCHER, PROCESS_KINDS, FaultError, refusal, write_faults
from bearcat.scenarios.schema import Scenario

log = logging.getLogger(__name__)

ENDING = ("peer ", "vehicle ")  # how the last line of a peer's or a vehicle's log starts
STARTUP = 60.0  # s for every peer to come up
GRACE = 5.0  # s past the time limit before the launcher stops a game itself
STOP_WAIT = 5.0  # s a peer gets to exit after the stop command, and again after SIGTERM
LOOK = 0.5  # s between looks at who joined the router from other machines
VEHICLE = "udpin://0.0.0.0:14540"  # where a UAV peer started by hand listens for its vehicle (PX4 SITL's)


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


def free_port(kind=socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


BEARCAT = (sys.executable, "-m", "bearcat")  # this very installation, whatever is on the PATH


def vehicle_command(scenario: Scenario, k: int, port: int) -> list[str]:
    """The emulator of the scenario's UAV ``k``: system id k + 1, home where it takes off."""
    lat, lon = scenario.map.to_geodetic(*scenario.uavs[k].start)
    return [
        *BEARCAT,
        "vehicle",
        "--connect",
        f"udpout:127.0.0.1:{port}",
        "--sysid",
        str(k + 1),
        "--home",
        f"{lat:.8f},{lon:.8f},0",
        "--max-speed",
        str(scenario.uavs[k].speed),
    ]


def peer_command(
    role: str,
    scenario_ref: str,
    agent: str,
    endpoint: str,
    seed: int,
    netem: str,
    out: Path | None,
    certs: Path,
    transport: str = "tcp",
    *,
    program: tuple[str, ...] = BEARCAT,
) -> list[str]:
    """The command that starts peer ``agent`` in ``role``, writing its logs into run directory ``out`` if given."""
    return [
        *program,
        "peer",
        role,
        "--scenario",
        scenario_ref,
        "--id",
        agent,
        "--connect",
        endpoint,
        "--mode",
        "client",
        "--seed",
        str(seed),
        "--netem",
        netem,
        "--transport",
        transport,
        *(() if out is None else ("--out", str(out))),
        "--certs",
        str(certs),
    ]


def started_by_hand(scenario: Scenario, joins: tuple[str, ...]) -> set[str]:
    """The agents whose peers a person starts: those driven from a keyboard, and those named in ``joins``."""
    return set(joins) | {a.id for a in scenario.agents if a.behaviour == "keyboard"}


def preflight(
    scenario: Scenario,
    plan: tuple,
    *,
    transport: str,
    secure: bool,
    certs: Path | None,
    phones: tuple[str, ...],
    joins: tuple[str, ...] = (),
    listen: tuple[Endpoint, ...] = (),
    page: tuple[str, int] = ("0.0.0.0", 8443),
) -> None:
    """One sentence for what would make a run of ``scenario`` fail, said
    before anything is solved or started."""
    if (why := refusal(plan, "live")) is not None:
        raise FaultError(why)
    peers = [*scenario.ids, *(u.id for u in scenario.uavs)]
    unknown = sorted(set(joins) - set(peers))
    if unknown:
        raise BusError(
            f"{scenario.source}: there is no agent or UAV {unknown[0]!r} to join by hand; they are {', '.join(peers)}"
        )
    for k, fault in enumerate(plan):
        if fault.kind in PROCESS_KINDS and fault.target in started_by_hand(scenario, joins):
            raise FaultError(
                f"fault[{k}] ({fault.kind}) targets {fault.target}, whose peer is started by hand, "
                "not by the launcher: it has no process of the launcher's to act on"
            )
    if secure and transport != "tcp":
        raise BusError(
            f"a --secure run carries everything over tls/, which is TCP: transport {transport!r} cannot be secured"
        )
    if certs is not None:
        covering(certs, scenario, phones)
    else:
        members(scenario, phones)  # every phone names an agent
    remote.check_listen(listen, secure=secure)
    for endpoint in listen:
        if not endpoint.wildcard and not is_local(endpoint.host):
            raise BusError(f"--listen {endpoint}: no interface of this machine has the address {endpoint.host}")
    if secure and certs is not None and listen:
        named = hosts_named(certs, LAUNCHER)
        remote.uncovered(listen, local_addresses(), named, str(certs / f"{LAUNCHER}.pem"))
    if set(phones) - set(joins):
        _link_host(page[0], listen)  # a phone must be told an address it reaches


def launch(
    scenario: Scenario,
    scenario_ref: str,
    out: Path,
    *,
    seed: int,
    netem: str,
    transport: str | None = None,
    network: str = "shim",
    say=print,
    startup: float = STARTUP,
    faults: tuple | None = None,
    certs: Path | None = None,
    secure: bool = False,
    phones: tuple[str, ...] = (),
    joins: tuple[str, ...] = (),
    page: tuple[str, int] = ("0.0.0.0", 8443),
    provisional: bool = False,
    listen: tuple[Endpoint, ...] = (),
) -> LiveOutcome:
    """Run ``scenario`` live; ``scenario_ref`` is how the peers load it (a name or a path);
    ``certs`` a directory of certificates for every peer (``bearcat certs
    init``; default: a new authority for this run alone, in ``out/certs``);
    ``secure`` puts the router on ``tls/`` with mutual TLS and the access
    control list of ``bus.access``; the agents of ``phones`` are played from
    real phones, whose pages are served from ``page`` (host, first port) on;
    the peers of the agents and UAVs in ``joins`` are started by hand, not
    here (see the module's docstring), on this machine or, with ``listen``,
    on others: the router takes their peers on those endpoints too
    (``runtime.remote``); ``transport`` is how best-effort messages
    travel (default: the scenario's);
    ``network`` "kernel" puts the peers behind a kernel network that impairs
    their packets, "shim" leaves the impairment to each peer's shim;
    ``faults`` is the fault plan to apply (default: the scenario's);
    a ``provisional`` ground station starts on provisional sets where the
    scenario's are not cached, and takes those up once solved."""
    plan = scenario.faults if faults is None else tuple(faults)
    transport = transport or scenario.transport
    preflight(
        scenario,
        plan,
        transport=transport,
        secure=secure,
        certs=certs,
        phones=phones,
        joins=joins,
        listen=listen,
        page=page,
    )
    full = next((f for f in plan if f.kind == "disk-full"), None)
    with SmallDisk(out, full.size) if full is not None else nullcontext() as disk:
        outcome = _play(
            scenario,
            scenario_ref,
            out,
            plan,
            seed=seed,
            netem=netem,
            transport=transport,
            network=network,
            say=say,
            startup=startup,
            fill=None if disk is None else disk.fill,
            certs=certs,
            secure=secure,
            phones=phones,
            joins=joins,
            page=page,
            provisional=provisional,
            listen=listen,
        )
    if full is not None:  # the disk is back: say what the full one could not take
        _rewrite_outcome(out, outcome)
    _say_how_they_ended(out / "peers", outcome.peers)
    try:
        finish_run(out, scenario)
    except OSError as exc:
        say(f"the recording could not be made: {exc}")
    return outcome


def _play(
    scenario,
    scenario_ref,
    out,
    plan,
    *,
    seed,
    netem,
    transport,
    network,
    say,
    startup,
    fill,
    certs,
    secure,
    phones,
    joins,
    page,
    provisional,
    listen,
) -> LiveOutcome:
    """Start the peers, play, stop them; the outcome, written beside what the run recorded if the disk lets it."""
    lease_ms = round(1000 * scenario.lease)
    out.mkdir(parents=True, exist_ok=True)
    (out / "peers").mkdir(exist_ok=True)
    write_scenario(out, scenario)
    processes.begin(out)
    run_flags: tuple[str, ...] = ("--secure",) if secure else ()
    if plan:
        write_faults(out / "faults.toml", plan)
        run_flags += ("--faults", str((out / "faults.toml").resolve()))
    port = free_port()
    game = scenario.name
    places: LocalPeers
    if network == "kernel":
        places = KernelPeers(port, netem, seed, report=out / "network.json", secure=secure)
    else:
        places = LocalPeers(port, secure=secure)
    endpoint = places.loopback
    addresses = local_addresses() if any(e.wildcard for e in listen) else ()
    given = certs
    # The launcher is the hub: a router every peer joins as a client. A mesh
    # of peers costs a link per pair, and with dozens of peers on a small
    # host it delays and drops fixes (benchmarks/field.py, --mode).
    with (
        places,
        run_authority(
            out, scenario, certs, phones=phones, hosts=(*places.hosts, *remote.hosts(listen, addresses))
        ) as certs,
        ZenohSession(
            LAUNCHER,
            config(
                listen=[*places.listen, *remote.router_endpoints(listen, secure=secure)],
                mode="router",
                lease_ms=lease_ms,
                tls=Credentials(certs, LAUNCHER) if secure else None,
                access=access_control(game, members(scenario, phones)) if secure else None,
            ),
            credentials=Credentials(certs, LAUNCHER),
        ) as session,
        closing(EventLog(out / "events.jsonl")) as record,
    ):
        for name, pid in places.own_processes().items():
            processes.record(out, name, pid)
        say(places.describe(netem))
        named = hosts_named(certs, LAUNCHER) if secure and given is not None else None
        elsewhere = [str(e) for e in remote.reachable_at(listen, addresses, named)]
        if listen:
            say(_listening(elsewhere, secure))
        # Where to connect another peer by hand (a keyboard walker, a real phone's bridge).
        where = {
            "endpoint": endpoint,
            "elsewhere": elsewhere,
            "game": scenario.name,
            "certs": str(certs),
            "network": places.host_side(),
        }
        (out / "endpoint.json").write_text(json.dumps(where) + "\n")
        inbox = Inbox(LAUNCHER)
        budget = SenderBudget()
        final: dict = {}
        alive: set[str] = set()
        lock = threading.Lock()
        injector: LiveFaults | None = None

        def within_budget(sender, key, now) -> bool:
            """Whether what ``sender`` put on ``key`` may cost the record a line (under the lock)."""
            if budget.allow(sender, key, now):
                return True
            for (who, where), n in budget.news(now).items():
                record.note(now, "over-budget", sender=who, receiver=LAUNCHER, key=where, dropped=n)
            return False

        def seen(key, payload, sender):
            now = time.time()
            with lock:
                if not within_budget(sender, key, now):
                    return
            message = inbox.accept(key, payload)
            with lock:
                if message is None:
                    record.refused(now, sender, LAUNCHER, key, "undecodable or wrong for its key")
                    return
                record.sent(now, sender, key, message)
                if isinstance(message, GameState) and message.phase == "ended" and "state" not in final:
                    final["state"] = message
            if injector is not None:
                injector.saw(message, now)

        def forged(key, claimed, category, reason):
            now = time.time()
            with lock:
                if within_budget(claimed, key, now):
                    record.refused(now, claimed, LAUNCHER, key, f"{category}: {reason}")

        session.on_refused = forged

        def liveliness(key, up):
            with lock:
                (alive.add if up else alive.discard)(key)
                record.note(time.time(), "alive" if up else "gone", key=key)

        session.subscribe(keys.game_wide(game), seen)
        session.subscribe_liveliness(keys.every(game, "alive"), liveliness)

        by_hand = started_by_hand(scenario, joins)
        expected = {keys.alive(game, "referee", "referee"), keys.alive(game, "ground-station", GROUND)}
        expected |= {keys.alive(game, "phone" if a.id in phones else "walker", a.id) for a in scenario.agents}
        expected |= {keys.alive(game, "uav", u.id) for u in scenario.uavs}
        if scenario.uavs:
            expected.add(keys.alive(game, "ground-station", "uav-tasking"))
        children: dict[str, subprocess.Popen] = {}
        started_at = None
        reason = None
        try:

            def command(role: str, name: str, *extra: str):
                return lambda at: [
                    *peer_command(role, scenario_ref, name, at, seed, netem, out, certs, transport),
                    *places.peer_flags,
                    *run_flags,
                    *extra,
                ]

            how: dict[str, tuple] = {}  # peer -> (role, flags): how to start it again

            def start(name: str, *, again: bool = False) -> subprocess.Popen:
                role, extra = how[name]
                log = out / "peers" / f"{name}.log"
                if again:
                    extra = (*extra, "--resume")
                # The ground station and the phones' bridges stay on the laptop: a real phone's network is real.
                colocated = role in ("ground-station", "phone")
                peer = places.start(name, command(role, name, *extra), log, colocated=colocated, again=again)
                processes.record(out, name, peer.pid)
                return peer

            how[GROUND] = (
                "ground-station",
                (*(("--judge", "fixes") if phones else ()), *(("--provisional",) if provisional else ())),
            )
            how |= {a.id: ("walker", ()) for a in scenario.agents if a.id not in by_hand and a.id not in phones}
            pages = _pages(tuple(p for p in phones if p not in by_hand), page, out)
            how |= {name: server_how for name, (_, server_how) in pages.items()}
            for name in list(how):
                children[name] = start(name)
            link_host = _link_host(page[0], listen) if pages else ""
            for name, (server, _) in pages.items():
                _say_link(name, server, children[name], say, link_host)
            for k, uav in enumerate(scenario.uavs):
                if uav.id in by_hand:
                    continue
                port = free_port(socket.SOCK_DGRAM)
                how[uav.id] = ("uav", ("--vehicle", f"udpin://0.0.0.0:{port}", "--sysid", str(k + 1), "--emulated"))
                flyer = children[uav.id] = start(uav.id)
                vehicle = f"vehicle-{uav.id}"
                children[vehicle] = places.start_vehicle(
                    flyer, vehicle_command(scenario, k, port), out / "peers" / f"{vehicle}.log"
                )
                processes.record(out, vehicle, children[vehicle].pid)
            # A peer started by hand elsewhere fetches the scenario from the
            # ground station, and keeps its logs on its own machine.
            at, ref, logs = (elsewhere[0], f"zenoh:{game}", None) if elsewhere else (endpoint, scenario_ref, out)
            program = ("bearcat",) if elsewhere else BEARCAT  # another machine's own installation
            guarded = ["--secure"] if secure else []
            uavs = [u.id for u in scenario.uavs]
            if elsewhere and not by_hand:
                say("router: no agent or UAV is left for another machine to start; --joins AGENT leaves one")
            for name in (p for p in (*scenario.ids, *uavs) if p in by_hand):
                role = "uav" if name in uavs else "walker"
                peer = peer_command(role, ref, name, at, seed, netem, logs, certs, transport, program=program)
                if role == "uav":
                    peer += ["--vehicle", VEHICLE]
                bridge = [*program, "phone", "--connect", at, "--game", game, "--id", name, "--certs", str(certs)]
                bridge += [] if logs is None else ["--out", str(logs)]
                chosen = bridge if name in phones else peer
                say(_joining(scenario, name, name in phones, chosen + guarded, certs=certs, elsewhere=bool(elsewhere)))
            deadline = time.monotonic() + (startup if not (by_hand or phones) else 10 * startup)
            arrived: set[remote.Arrival] = set()
            look = time.monotonic()
            while True:
                with lock:
                    missing = sorted(expected - alive)
                if elsewhere and time.monotonic() >= look:  # who came from other machines, as they come
                    look = time.monotonic() + LOOK
                    for arrival in remote.arrivals(session.links(), arrived):
                        say(f"{game}: {arrival.describe()}")
                        with lock:
                            record.note(time.time(), "joined", **vars(arrival))
                if not missing:
                    break
                dead = [n for n, p in children.items() if p.poll() is not None]
                if dead:
                    reason = f"peer {dead[0]} exited with code {children[dead[0]].returncode} before the start"
                    break
                if time.monotonic() > deadline:
                    reason = f"peers not up after {startup:g} s: {', '.join(k.rsplit('/', 1)[-1] for k in missing)}"
                    break
                time.sleep(0.05)
            if reason is None:
                if plan:
                    injector = LiveFaults(
                        plan,
                        game=game,
                        session=session,
                        record=record,
                        lock=lock,
                        children=children,
                        restart=lambda name: start(name, again=True),
                        network=getattr(places, "network", None),
                        logs=out / "peers",
                        fill=fill,
                    )
                begin = Control(t=time.time(), command="start", seq=1)
                places.game_started(begin.t)
                session.put(keys.control(game), encode(begin))
                if injector is not None:
                    injector.begin(begin.t)
                started_at = time.monotonic()
                say(f"{game}: {len(expected)} peers up; game started")
                limit = scenario.time_limit + GRACE
                reason = _supervise(children, final, lock, started_at, limit, scenario.lease, injector, out / "peers")
        except KeyboardInterrupt:
            reason = "interrupted"
        finally:
            if injector is not None:
                injector.close()
            codes = _stop_all(session, game, children, final, lock, reason)
            state = final.get("state")
            outcome = LiveOutcome(
                scenario=game,
                winner=state.winner if state else None,
                reason=state.reason if state else (reason or "stopped"),
                elapsed=state.elapsed if state else (0.0 if started_at is None else time.monotonic() - started_at),
                ended=state is not None,
                peers=codes,
                failures=agent_failures(out / "peers"),
                out=str(out),
                faults=[] if injector is None else injector.applied,
            )
            record.note(time.time(), "outcome", **vars(outcome))
            _keep(out, outcome, record, say)
    return outcome


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
        keyboard = scenario.agent(name).behaviour == "keyboard"
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
        server = PageServer(host=page[0], port=page[1] + k, token=new_token())
        token_file = out / "phones" / f"{name}.token"
        token_file.touch(mode=0o600)
        token_file.write_text(server.token + "\n")
        pages[name] = (server, ("phone", ("--page", f"{server.host}:{server.port}", "--token-file", str(token_file))))
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


def _link_host(host: str, listen: tuple[Endpoint, ...]) -> str:
    """The address a phone is told to open pages served at ``host`` at:
    ``host`` itself, unless it is every interface; then the one the router
    takes other machines at (the field's network), else what this
    machine's network says (``bus.addresses.reachable``)."""
    return remote.link_host(host, listen) or reachable(host)


def _listening(elsewhere: list[str], secure: bool) -> str:
    """What the launcher says of the endpoints where peers on other machines join."""
    if not elsewhere:
        return "router: takes peers from other machines, but this machine has no address besides the loopback yet"
    said = "router: peers on other machines join at " + ", ".join(elsewhere)
    if not secure:
        said += " (unsecured: whoever reaches it reads every message; --secure guards it)"
    return said


def _keep(out: Path, outcome: LiveOutcome, record: EventLog, say) -> None:
    """Write the outcome; a disk that refuses it gets it said instead, and so do the lines it refused."""
    text = json.dumps(vars(outcome), indent=2) + "\n"
    try:
        (out / "outcome.json").write_text(text)
    except OSError as exc:
        say(f"cannot write {out / 'outcome.json'} ({exc.strerror or exc}); the outcome:\n{text}")
    if record.lost:
        say(f"{out / 'events.jsonl'}: the disk refused {record.lost} line(s) ({record.failure})")


def _say_how_they_ended(peers: Path, codes: dict[str, int | None]) -> None:
    """A peer killed by a signal, or whose disk was full, could not say how it
    ended: the launcher says it in its log, from its exit code."""
    for name, code in codes.items():
        log_path = peers / f"{name}.log"
        lines = log_path.read_text(errors="replace").splitlines() if log_path.exists() else []
        if lines and lines[-1].startswith(ENDING):
            continue
        how = f"killed by signal {-code}" if code is not None and code < 0 else f"exited with code {code}"
        if code is not None and code >= 0:
            how += " without a word (its log could not be written)"
        with open(log_path, "a", encoding="utf-8") as log_file:
            log_file.write(f"peer {name}: {how}\n")


def _rewrite_outcome(out: Path, outcome: LiveOutcome) -> None:
    """Write the outcome again where a full disk left it empty or cut short."""
    path = out / "outcome.json"
    try:
        json.loads(path.read_text())
    except (OSError, ValueError):
        path.write_text(json.dumps(vars(outcome), indent=2) + "\n")


def agent_failures(peers: Path) -> dict[str, int]:
    """How often each agent raised, from the ``failed`` events of the peers' logs in ``peers``."""
    counts: Counter[str] = Counter()
    for path in sorted(peers.glob("*.jsonl")):
        counts.update(e["agent"] for e in read_events(path) if e["event"] == FAILED)
    return dict(sorted(counts.items()))


def _why(logs: Path, name: str) -> str:
    """What a peer that exited said of why (``peer NAME: REASON``, its log's last words), as a clause."""
    try:
        lines = (logs / f"{name}.log").read_text(errors="replace").splitlines()
    except OSError:
        return ""
    said = next((line for line in reversed(lines) if line.startswith(f"peer {name}: ")), None)
    return "" if said is None else f" ({said.split(': ', 1)[1][:120]})"


def _supervise(
    children, final, lock, started_at: float, limit: float, lease: float, injector, logs: Path
) -> str | None:
    """Wait for the end of the game; why the launcher had to end it, if it did
    (a dead walker's forfeit is the referee's to call, once its ``lease`` to
    rejoin has run out; a peer a fault restarts is not dead)."""
    gone_since = None
    while True:
        with lock:
            if "state" in final:
                return None
        if injector is not None:
            injector.respawn()
        downed = {} if injector is None else dict(injector.out_of_play)
        dead = [n for n, p in children.items() if p.poll() is not None and not downed.get(n, ("", False))[1]]
        if dead:
            if GROUND in dead:
                if GROUND in downed:
                    return f"the ground station is gone: {downed[GROUND][0]}"
                return f"the ground station exited with code {children[GROUND].returncode}{_why(logs, GROUND)}"
            gone_since = gone_since or time.monotonic()
            if time.monotonic() - gone_since > lease + 3.0:
                return f"peer {dead[0]} exited with code {children[dead[0]].returncode}{_why(logs, dead[0])}"
        if time.monotonic() - started_at > limit:
            return f"no result within {limit:g} s"
        time.sleep(0.05)


def _stop_all(session, game: str, children, final, lock, reason) -> dict[str, int | None]:
    with lock:
        ended = "state" in final
    if not ended and children:
        try:
            stop = Control(t=time.time(), command="stop", reason=(reason or "")[:200], seq=2)
            session.put(keys.control(game), encode(stop))
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
