"""Launching a live run: every peer its own process over Zenoh on this host.

The launcher solves what the ground station will need first (so no peer
starts against an empty cache): the scenario's sets, or provisional ones
a ``provisional`` ground station answers from until the scenario's, solved
behind the game, are in the cache. It listens on a free loopback port that every
peer connects to, starts the ground station and one walker per agent (and for each UAV a
``bearcat vehicle`` emulator on its own UDP port, PX4 SITL's 14540 + i
convention moved to free ports, with a UAV peer flying it), waits
until every peer's liveliness token is up, sends the start command and
supervises: the run ends when the referee says so (a walker whose peer
died forfeits once its lease to rejoin runs out), at the time limit, or on
Ctrl-C; a ground station or UAV peer that dies is started again as the
scenario's ``[supervision]`` says (``supervisor``), and one that dies too
often ends the run. A run whose launcher died is taken up again with
``taken_up`` (``resume``). In every case the launcher then stops every peer it started
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
import time
from contextlib import closing, nullcontext
from pathlib import Path

from bearcat.agents.ground_station.event_log import EventLog
from bearcat.agents.ground_station.rerun_recording import finish_run
from bearcat.bus.access import access_control
from bearcat.bus.addresses import is_local, local_addresses
from bearcat.bus.endpoints import Endpoint
from bearcat.bus.errors import BusError
from bearcat.bus.identity import Credentials, hosts_named
from bearcat.bus.zenoh_session import ZenohSession, config
from bearcat.runtime import processes, remote
from bearcat.runtime.credentials import covering, members, run_authority
from bearcat.runtime.live_run import STARTUP, LiveOutcome, LiveRun, RunSettings, link_host_of
from bearcat.runtime.peer_commands import free_port, started_by_hand
from bearcat.runtime.peers import KernelPeers, LocalPeers
from bearcat.runtime.resume import Launched, last_record, launcher_of, write_launched
from bearcat.runtime.run_directory import write_scenario
from bearcat.runtime.small_disk import SmallDisk
from bearcat.scenarios.faults import BY_ITSELF, LAUNCHER, NOT_BY_ITSELF, FaultError, refusal, write_faults
from bearcat.scenarios.schema import Scenario

ENDING = ("peer ", "vehicle ")  # how the last line of a peer's or a vehicle's log starts


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
        if fault.kind in NOT_BY_ITSELF and fault.target in started_by_hand(scenario, joins):
            raise FaultError(
                f"fault[{k}] ({fault.kind}) targets {fault.target}, whose peer is started by hand: "
                f"{NOT_BY_ITSELF[fault.kind]} (a peer started by hand applies {', '.join(BY_ITSELF)} itself)"
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
        link_host_of(page[0], listen)  # a phone must be told an address it reaches


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
    taken_up: Launched | None = None,
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
    scenario's are not cached, and takes those up once solved; ``taken_up``
    is how the run in ``out``, whose launcher died, was launched: this
    launch takes it up again (``runtime.resume``)."""
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
        settings = RunSettings(
            scenario,
            scenario_ref,
            out,
            plan,
            seed=seed,
            netem=netem,
            transport=transport,
            say=say,
            startup=startup,
            fill=None if disk is None else disk.fill,
            secure=secure,
            phones=phones,
            joins=joins,
            page=page,
            provisional=provisional,
            listen=listen,
            resumed=taken_up is not None,
        )
        outcome = _play(settings, network=network, certs=certs, taken_up=taken_up)
    if full is not None:  # the disk is back: say what the full one could not take
        _rewrite_outcome(out, outcome)
    _say_how_they_ended(out / "peers", outcome.peers)
    try:
        finish_run(out, scenario)
    except OSError as exc:
        say(f"the recording could not be made: {exc}")
    return outcome


def _play(settings: RunSettings, *, network: str, certs: Path | None, taken_up: Launched | None) -> LiveOutcome:
    """Open the run's directory, network, authority, router and record, and play the run in them."""
    s = settings
    out, scenario = s.out, s.scenario
    if taken_up is None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "peers").mkdir(exist_ok=True)
        write_scenario(out, scenario)
        processes.begin(out)
        if s.plan:
            write_faults(out / "faults.toml", s.plan)
    port = free_port() if taken_up is None else taken_up.port
    launched = Launched(
        scenario_ref=s.scenario_ref,
        seed=s.seed,
        netem=s.netem,
        transport=s.transport,
        network=network,
        secure=s.secure,
        certs=None if certs is None else str(certs.resolve()),
        phones=s.phones,
        joins=s.joins,
        page=s.page,
        provisional=s.provisional,
        listen=tuple(str(e) for e in s.listen),
        port=port,
        launchers=(*(() if taken_up is None else taken_up.launchers), launcher_of()),
    )
    write_launched(out, launched)
    places: LocalPeers
    if network == "kernel":
        places = KernelPeers(port, s.netem, s.seed, report=out / "network.json", secure=s.secure)
    else:
        places = LocalPeers(port, secure=s.secure)
    addresses = local_addresses() if any(e.wildcard for e in s.listen) else ()
    given = certs
    # The launcher is the hub: a router every peer joins as a client. A mesh
    # of peers costs a link per pair, and with dozens of peers on a small
    # host it delays and drops fixes (benchmarks/field.py, --mode).
    with (
        places,  # entered first: a kernel network's addresses are known once it is up
        run_authority(
            out,
            scenario,
            certs,
            phones=s.phones,
            hosts=(*places.hosts, *remote.hosts(s.listen, addresses)),
            again=taken_up is not None,
        ) as certs,
        ZenohSession(
            LAUNCHER,
            config(
                listen=[*places.listen, *remote.router_endpoints(s.listen, secure=s.secure)],
                mode="router",
                lease_ms=round(1000 * scenario.lease),
                tls=Credentials(certs, LAUNCHER) if s.secure else None,
                access=access_control(scenario.name, members(scenario, s.phones)) if s.secure else None,
            ),
            credentials=Credentials(certs, LAUNCHER),
        ) as session,
        closing(EventLog(out / "events.jsonl", append=taken_up is not None)) as record,
    ):
        if taken_up is not None:
            since = last_record(out)
            now = time.time()
            record.note(now, "resumed", since=since, gap=None if since is None else now - since)
            s.say(f"{scenario.name}: taken up again after {0.0 if since is None else now - since:.1f} s")
        for name, pid in places.own_processes().items():
            processes.record(out, name, pid)
        s.say(places.describe(s.netem))
        named = hosts_named(certs, LAUNCHER) if s.secure and given is not None else None
        elsewhere = [str(e) for e in remote.reachable_at(s.listen, addresses, named)]
        if s.listen:
            s.say(_listening(elsewhere, s.secure))
        # Where to connect another peer by hand (a keyboard walker, a real phone's bridge).
        where = {
            "endpoint": places.loopback,
            "elsewhere": elsewhere,
            "game": scenario.name,
            "certs": str(certs),
            "network": places.host_side(),
        }
        (out / "endpoint.json").write_text(json.dumps(where) + "\n")
        return LiveRun(settings, places, session, record, certs, elsewhere).play()


def _listening(elsewhere: list[str], secure: bool) -> str:
    """What the launcher says of the endpoints where peers on other machines join."""
    if not elsewhere:
        return "router: takes peers from other machines, but this machine has no address besides the loopback yet"
    said = "router: peers on other machines join at " + ", ".join(elsewhere)
    if not secure:
        said += " (unsecured: whoever reaches it reads every message; --secure guards it)"
    return said


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
