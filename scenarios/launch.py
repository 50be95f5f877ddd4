"""Launching a live run: every peer its own process over Zenoh on this host.

The launcher solves what the ground station will need first (so no peer
starts against an empty cache), listens on a free loopback port that every
peer connects to, starts the ground station and one walker per agent (and for each UAV a
``bearcat vehicle`` emulator on its own UDP port, PX4 SITL's 14540 + i
convention moved to free ports, with a UAV peer flying it), waits
until every peer's liveliness token is up, sends the start command and
supervises: the run ends when the referee says so, when a peer process dies
(the referee sees its token vanish and ends the game; the launcher ends the
run itself if the ground station is the one that died), at the time limit,
or on Ctrl-C. In every case the launcher then stops every peer it started
(a stop command, then SIGTERM, then SIGKILL) and leaves no process behind.
Agents driven from a keyboard are not started here: the launcher prints the
``bearcat peer`` command for a person to run in a terminal, and waits.

The launcher's own session records every message of the game it sees into
``events.jsonl``; each peer writes what it sent and received, what its
network shim did to the messages it received and its agents' failures into
``peers/NAME.jsonl``, and its log into ``peers/NAME.log``. The outcome counts
the failures of each agent from those logs.
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
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path

from bearcat.agents.ground_station.event_log import EventLog, read_events
from bearcat.agents.ground_station.rerun_recording import finish_run
from bearcat.bus import keys
from bearcat.bus.codec import Inbox, encode
from bearcat.bus.messages import Control, GameState
from bearcat.bus.zenoh_session import ZenohSession, config
from bearcat.scenarios.dispatch import FAILED
from bearcat.scenarios.peers import KernelPeers, LocalPeers
from bearcat.scenarios.schema import Scenario

log = logging.getLogger(__name__)

GROUND = "gs"
STARTUP = 60.0  # s for every peer to come up
GRACE = 5.0  # s past the time limit before the launcher stops a game itself
STOP_WAIT = 5.0  # s a peer gets to exit after the stop command, and again after SIGTERM


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


def free_port(kind=socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def vehicle_command(scenario: Scenario, k: int, port: int) -> list[str]:
    """The emulator of the scenario's UAV ``k``: system id k + 1, home where it takes off."""
    lat, lon = scenario.map.to_geodetic(*scenario.uavs[k].start)
    return [
        sys.executable,
        "-m",
        "bearcat",
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
    role: str, scenario_ref: str, agent: str, endpoint: str, seed: int, netem: str, out: Path, transport: str = "tcp"
) -> list[str]:
    return [
        sys.executable,
        "-m",
        "bearcat",
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
        "--out",
        str(out),
    ]


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
) -> LiveOutcome:
    """Run ``scenario`` live; ``scenario_ref`` is how the peers load it (a name or a path);
    ``transport`` is how best-effort messages travel (default: the scenario's);
    ``network`` "kernel" puts the peers behind a kernel network that impairs
    their packets, "shim" leaves the impairment to each peer's shim."""
    transport = transport or scenario.transport
    lease_ms = round(1000 * scenario.lease)
    out.mkdir(parents=True, exist_ok=True)
    (out / "peers").mkdir(exist_ok=True)
    port = free_port()
    places = KernelPeers(port, netem, seed, report=out / "network.json") if network == "kernel" else LocalPeers(port)
    endpoint = places.loopback
    # The launcher is the hub: a router every peer joins as a client. A mesh
    # of peers costs a link per pair, and with dozens of peers on a small
    # host it delays and drops fixes (benchmarks/field.py, --mode).
    with (
        places,
        ZenohSession("launcher", config(listen=places.listen, mode="router", lease_ms=lease_ms)) as session,
        closing(EventLog(out / "events.jsonl")) as record,
    ):
        say(places.describe(netem))
        # Where to connect another peer by hand (a keyboard walker, a real phone's bridge).
        (out / "endpoint.json").write_text(json.dumps({"endpoint": endpoint, "game": scenario.name}) + "\n")
        inbox = Inbox("launcher")
        final: dict = {}
        alive: set[str] = set()
        lock = threading.Lock()
        game = scenario.name

        def seen(key, payload, sender):
            message = inbox.accept(key, payload)
            with lock:
                if message is None:
                    record.refused(time.time(), sender, "launcher", key, "undecodable or wrong for its key")
                    return
                record.sent(time.time(), sender, key, message)
                if isinstance(message, GameState) and message.phase == "ended" and "state" not in final:
                    final["state"] = message

        def liveliness(key, up):
            with lock:
                (alive.add if up else alive.discard)(key)
                record.note(time.time(), "alive" if up else "gone", key=key)

        session.subscribe(keys.game_wide(game), seen)
        session.subscribe_liveliness(keys.every(game, "alive"), liveliness)

        keyboard = [a.id for a in scenario.agents if a.behaviour == "keyboard"]
        expected = {keys.alive(game, "referee", "referee"), keys.alive(game, "ground-station", GROUND)}
        expected |= {keys.alive(game, "walker", a.id) for a in scenario.agents}
        expected |= {keys.alive(game, "uav", u.id) for u in scenario.uavs}
        if scenario.uavs:
            expected.add(keys.alive(game, "ground-station", "uav-tasking"))
        children: dict[str, subprocess.Popen] = {}
        started_at = None
        reason = None
        try:

            def command(role: str, name: str, *extra: str):
                return lambda at: [
                    *peer_command(role, scenario_ref, name, at, seed, netem, out, transport),
                    *places.peer_flags,
                    *extra,
                ]

            roles = [("ground-station", GROUND)] + [("walker", a.id) for a in scenario.agents if a.id not in keyboard]
            for role, name in roles:
                log = out / "peers" / f"{name}.log"
                children[name] = places.start(name, command(role, name), log, colocated=name == GROUND)
            for k, uav in enumerate(scenario.uavs):
                port = free_port(socket.SOCK_DGRAM)
                fly = ("--vehicle", f"udpin://0.0.0.0:{port}", "--sysid", str(k + 1), "--emulated")
                flyer = children[uav.id] = places.start(
                    uav.id, command("uav", uav.id, *fly), out / "peers" / f"{uav.id}.log"
                )
                vehicle = f"vehicle-{uav.id}"
                children[vehicle] = places.start_vehicle(
                    flyer, vehicle_command(scenario, k, port), out / "peers" / f"{vehicle}.log"
                )
            for name in keyboard:
                say(
                    f"agent {name} is driven from a keyboard; in a terminal, run:\n  "
                    + " ".join(peer_command("walker", scenario_ref, name, endpoint, seed, netem, out, transport))
                )
            deadline = time.monotonic() + (startup if not keyboard else 10 * startup)
            while True:
                with lock:
                    missing = sorted(expected - alive)
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
                start = Control(t=time.time(), command="start")
                places.game_started(start.t)
                session.put(keys.control(game), encode(start))
                started_at = time.monotonic()
                say(f"{game}: {len(expected)} peers up; game started")
                reason = _supervise(children, final, lock, started_at, scenario.time_limit + GRACE)
        except KeyboardInterrupt:
            reason = "interrupted"
        finally:
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
            )
            record.note(time.time(), "outcome", **vars(outcome))
            (out / "outcome.json").write_text(json.dumps(vars(outcome), indent=2) + "\n")
    finish_run(out, scenario)
    return outcome


def agent_failures(peers: Path) -> dict[str, int]:
    """How often each agent raised, from the ``failed`` events of the peers' logs in ``peers``."""
    counts: Counter[str] = Counter()
    for path in sorted(peers.glob("*.jsonl")):
        counts.update(e["agent"] for e in read_events(path) if e["event"] == FAILED)
    return dict(sorted(counts.items()))


def _supervise(children, final, lock, started_at: float, limit: float) -> str | None:
    """Wait for the end of the game; why the launcher had to end it, if it did."""
    gone_since = None
    while True:
        with lock:
            if "state" in final:
                return None
        dead = [n for n, p in children.items() if p.poll() is not None]
        if dead:
            if GROUND in dead:
                return f"the ground station exited with code {children[GROUND].returncode}"
            # The referee sees a walker's token vanish and ends the game; give it a moment.
            gone_since = gone_since or time.monotonic()
            if time.monotonic() - gone_since > 3.0:
                return f"peer {dead[0]} exited with code {children[dead[0]].returncode}"
        if time.monotonic() - started_at > limit:
            return f"no result within {limit:g} s"
        time.sleep(0.05)


def _stop_all(session, game: str, children, final, lock, reason) -> dict[str, int | None]:
    with lock:
        ended = "state" in final
    if not ended and children:
        try:
            session.put(keys.control(game), encode(Control(t=time.time(), command="stop", reason=(reason or "")[:200])))
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
