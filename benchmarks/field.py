"""The field simulator's speed: how fast ``simulate`` runs a game against
the wall clock, and the fix-to-guidance latency over Zenoh on loopback.

    python benchmarks/field.py                 # both, 10 and 50 phones
    python benchmarks/field.py --phones 10     # latency with 10 phones only
    python benchmarks/field.py --simulate-only
    sudo python benchmarks/field.py --latency-only --kernel   # also every phone in its own namespace
    python benchmarks/field.py --latency-only --phones 10 --secure   # also sealed, over tls/ with access control

Latency: N phone processes each publish a GPS fix ten times a second and
wait for the guidance that answers it; the ground station (the real
``GuidanceService`` under the live runtime, ``ideal`` network) runs in this
process. A fix is answered when a guidance arrives whose report of that
phone is that fix or a newer one (guidance shows the latest fix); latency is
the time from publishing the fix to that arrival, on one clock. Lost fixes
are counted where they should arrive, at the ground station. The peer it is compared
with is a bare Zenoh echo over the same links (no codec, no agents): the
ratio is what our layers cost on top of the transport.
With ``--kernel`` the same measurement runs again with every phone in a
network namespace of its own behind a kernel network under ``ideal`` (as
``bearcat run --network kernel`` places them, clients of the ground station
as a router): what the namespaces, the hub and its packet queue cost.
With ``--secure`` it runs again as ``bearcat run --secure`` joins peers:
every message sealed and checked (``bus.identity``), every phone a client
of the ground station as a router over ``tls/`` with mutual TLS and the
access control list (``bus.access``); the echo then goes over TLS too.
Targets: p99 under 20 ms with 10 phones and no fix unanswered; ``simulate``
at least 200x faster than real time for a 1 vs 1 game with 10 Hz guidance, on one core.

Each result is printed as it is measured. SIGTERM (or Ctrl-C) stops the
benchmark at once: the run under way is dropped, its phones are stopped,
and what is printed is what finished.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

GAME = "bench"
START_KEY = "bench/start"
STARTUP = 120.0  # s for every phone to come up
STOP_WAIT = 5.0  # s a phone has to go on SIGTERM before it is killed


class Interrupted(Exception):
    """SIGTERM or SIGINT: the benchmark stops, and its phones with it."""


def _stop_on_sigterm() -> None:
    """Make SIGTERM unwind the benchmark as Ctrl-C does, so that every phone
    is stopped on the way out. Called again after each ``asyncio.run``: the
    ground station's peer takes SIGTERM for its loop, and the loop puts the
    default action (death, leaving the phones behind) back as it closes."""
    signal.signal(signal.SIGTERM, _interrupt)


def _interrupt(signum, frame) -> None:
    raise Interrupted(f"stopped by {signal.Signals(signum).name}")


def _stop(procs: list[subprocess.Popen]) -> None:
    """Stop every phone still running: SIGTERM, then SIGKILL."""
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=STOP_WAIT)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def phone(args) -> None:
    """One phone process: fixes at 10 Hz, latencies of their answers to a JSON file."""
    import zenoh

    from bearcat.bus import keys
    from bearcat.bus.codec import decode, encode
    from bearcat.bus.identity import Credentials
    from bearcat.bus.messages import Fix, Guidance
    from bearcat.bus.zenoh_session import ZenohSession, config

    credentials = Credentials(args.certs, args.phone) if args.certs else None
    how = config(connect=[args.connect], listen=[], mode=args.mode, tls=credentials)
    with ZenohSession(args.phone, how, credentials=credentials) as session, zenoh.open(how) as bare:
        sent: dict[float, float] = {}
        latencies: list[float] = []
        echo_rtts: list[float] = []
        lock = threading.Lock()

        def on_guidance(key, payload, sender):
            now = time.time()
            message = decode(payload, key)
            if isinstance(message, Guidance):
                with lock:
                    for r in message.reports:
                        if r.agent == args.phone:
                            # This fix, and any older one still waiting, is now reflected on the screen.
                            for t in [t for t in sent if t <= r.t]:
                                latencies.append(now - sent.pop(t))

        def on_echo(sample):
            echo_rtts.append(time.time() - float(sample.payload.to_bytes().decode()))

        session.subscribe(keys.guidance(GAME, args.phone), on_guidance)
        taps = [bare.declare_subscriber(f"bench/echo/{args.phone}/back", on_echo)]
        # Every phone starts on the ground station's word, once all are up: in
        # namespaces the set-up of fifty takes longer than one's warm-up.
        started = threading.Event()
        taps.append(bare.declare_subscriber(START_KEY, lambda sample: started.set()))
        session.declare_token(keys.alive(GAME, "phone", args.phone))
        if not started.wait(STARTUP):
            raise SystemExit(f"phone {args.phone}: no start in {STARTUP:g} s")
        time.sleep(args.warmup + random.Random(args.phone).uniform(0.0, 0.1))  # phones out of step, as in a field
        end = time.time() + args.duration
        seq, due = 0, time.monotonic()
        while time.time() < end:
            seq += 1
            t = time.time()
            with lock:
                sent[t] = t
            lat, lon = 37.8719 + 1e-6 * (seq % 100), -122.2585
            session.put(
                keys.fix(GAME, args.phone),
                encode(Fix(agent=args.phone, seq=seq, t=t, lat=lat, lon=lon)),
                reliable=False,
            )
            bare.put(
                f"bench/echo/{args.phone}/out",
                str(time.time()).encode(),
                congestion_control=zenoh.CongestionControl.DROP,
            )
            due += 0.1
            time.sleep(max(due - time.monotonic(), 0))
        time.sleep(1.0)
        for tap in taps:
            tap.undeclare()
    Path(args.out).write_text(
        json.dumps({"latencies": latencies, "sent": seq, "answered": len(latencies), "echo": echo_rtts})
    )


def latency(n: int, duration: float, mode: str = "peer", kernel: bool = False, secure: bool = False) -> dict:
    import zenoh

    from bearcat.agents.ground_station.guidance import GuidanceService
    from bearcat.bus import keys
    from bearcat.bus.access import access_control
    from bearcat.bus.codec import Inbox
    from bearcat.bus.identity import Credentials, make_authority
    from bearcat.bus.zenoh_session import ZenohSession, config
    from bearcat.maps import load_map
    from bearcat.runtime.live import run_peer
    from bearcat.runtime.peer_commands import free_port

    port = free_port()
    scheme = "tls" if secure else "tcp"
    endpoint = f"{scheme}/127.0.0.1:{port}"
    ids = [f"p{k}" for k in range(n)]
    hub = "router" if mode == "client" else "peer"
    certs = tls = echo_tls = access = None
    if secure:
        certs = Path(tempfile.mkdtemp(prefix="bench-certs-")) / "certs"
        members = {"gs": "ground-station", "echo": "launcher", **dict.fromkeys(ids, "phone")}
        make_authority(certs, members)
        tls, echo_tls = Credentials(certs, "gs"), Credentials(certs, "echo")
        access = access_control(GAME, members)
        # The bare-Zenoh echo and the start signal are not the game's: allowed to all.
        access["rules"].append(
            {
                "id": "bench",
                "permission": "allow",
                "flows": ["ingress", "egress"],
                "messages": ["put", "declare_subscriber"],
                "key_exprs": ["bench/**"],
            }
        )
        for policy in access["policies"]:
            policy["rules"].append("bench")
    network = contextlib.nullcontext()
    if kernel:
        from bearcat.netem.kernel.network import KernelNetwork

        network = KernelNetwork("ideal", seed=0)
    # The bare-Zenoh peer, "echo", sends every ping straight back.
    with (
        network,
        ZenohSession(
            "gs",
            config(
                listen=[endpoint] + ([f"{scheme}/{network.router}:{port}"] if kernel else []),
                mode=hub,
                tls=tls,
                access=access,
            ),
            credentials=tls,
        ) as session,
        zenoh.open(
            config(connect=[endpoint], listen=[] if mode == "client" else None, mode=mode, tls=echo_tls)
        ) as echo,
    ):

        def back(sample):
            echo.put(
                str(sample.key_expr).rsplit("/", 1)[0] + "/back",
                sample.payload.to_bytes(),
                congestion_control=zenoh.CongestionControl.DROP,
            )

        echoing = echo.declare_subscriber("bench/echo/*/out", back)
        service = GuidanceService(GAME, load_map("field-50"), ids, rate=10.0)
        received: dict[str, set] = {pid: set() for pid in ids}

        def count(key, payload, sender):
            message = Inbox("count").accept(key, payload)
            if message is not None:
                received[message.agent].add(message.seq)

        session.subscribe(keys.every(GAME, "fix"), count)
        seen = set()
        session.subscribe_liveliness(keys.every(GAME, "alive"), lambda k, up: seen.add(k) if up else None)
        with tempfile.TemporaryDirectory() as tmp:

            def command(pid: str, at: str) -> list[str]:
                return [sys.executable, __file__, "--phone", pid, "--connect", at, "--duration", str(duration)] + [
                    "--warmup",
                    "3",
                    "--out",
                    f"{tmp}/{pid}.json",
                    "--mode",
                    mode,
                    *(["--certs", str(certs)] if certs else []),
                ]

            async def serve():
                task = asyncio.create_task(run_peer([service], session, GAME))
                deadline = time.monotonic() + STARTUP
                while sum("/phone/" in k for k in seen) < n and time.monotonic() < deadline and not task.done():
                    await asyncio.sleep(0.05)
                echo.put(START_KEY, b"")
                await asyncio.wait([task], timeout=duration + 12.0)
                task.cancel()
                (why,) = await asyncio.gather(task, return_exceptions=True)  # let the peer close its session
                # The peer takes SIGTERM and SIGINT for itself, and ends on them: the benchmark was told to stop.
                if isinstance(why, str) and why.startswith("interrupted"):
                    raise Interrupted(f"stopped: the ground station was {why}")
                if isinstance(why, Exception):
                    raise why

            procs: list[subprocess.Popen] = []
            try:
                for pid in ids:
                    if kernel:
                        at = f"{scheme}/{network.router}:{port}"
                        procs.append(network.spawn(pid, command(pid, at), log_file=subprocess.DEVNULL))
                    else:
                        procs.append(subprocess.Popen(command(pid, endpoint)))
                try:
                    asyncio.run(serve())
                finally:
                    _stop_on_sigterm()
                for p in procs:
                    p.wait(timeout=60)
            finally:
                _stop(procs)
            results = [json.loads(Path(f"{tmp}/{pid}.json").read_text()) for pid in ids]
        echoing.undeclare()
    lat = np.concatenate([r["latencies"] for r in results]) * 1e3
    rtt = np.concatenate([r["echo"] for r in results]) * 1e3
    sent = sum(r["sent"] for r in results)
    lost = sent - sum(len(seqs) for seqs in received.values())
    return {
        "phones": n,
        "fixes": sent,
        "lost": lost,
        "unanswered": sent - sum(r["answered"] for r in results),
        "p50_ms": float(np.percentile(lat, 50)),
        "p99_ms": float(np.percentile(lat, 99)),
        "echo_p50_ms": float(np.percentile(rtt, 50)),
        "echo_p99_ms": float(np.percentile(rtt, 99)),
    }


def simulate_speed(games: int):
    """One row per scenario and guidance, each as soon as it is measured:
    the scenarios as built (plain guidance), then with calibrated guidance,
    whose trackers and sampled values cost more per answer (with no
    calibration in the cache it takes the tracker's own margin, which costs
    a little more again)."""
    from bearcat.runtime.simulate import simulate
    from bearcat.scenarios.schema import load_scenario
    from bearcat.scenarios.variants import vary

    for uncertainty in ("none", "calibrated"):
        for name in ("fake-out-aided-defender", "fake-out", "go-no-go"):
            scenario = vary(load_scenario(name), {"guidance.uncertainty": uncertainty})
            simulate(scenario, seed=0)  # the solve and the first compiles are not what is timed
            game, wall = 0.0, 0.0
            for seed in range(games):
                t = time.perf_counter()
                outcome = simulate(scenario, seed=seed)
                wall += time.perf_counter() - t
                game += outcome.elapsed
            label = name if uncertainty == "none" else f"{name}, calibrated"
            yield {"scenario": label, "games": games, "game_s": game, "wall_s": wall, "speedup": game / wall}


def main() -> None:
    args = arguments().parse_args()
    if args.phone:
        return phone(args)
    _stop_on_sigterm()
    try:
        measure(args)
    except (Interrupted, KeyboardInterrupt) as stop:
        why = str(stop) or "stopped by SIGINT"
        raise SystemExit(f"field.py: {why}; the results printed are those that finished") from None


def arguments() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--phones", type=int, nargs="+", default=[10, 50])
    parser.add_argument("--duration", type=float, default=20.0, help="seconds of fixes per phone")
    parser.add_argument("--games", type=int, default=5)
    parser.add_argument("--simulate-only", action="store_true")
    parser.add_argument("--latency-only", action="store_true")
    parser.add_argument(
        "--mode",
        choices=("peer", "client"),
        default="peer",
        help="phones as Zenoh peers (a full mesh) or as clients of the ground station as a router",
    )
    parser.add_argument(
        "--kernel", action="store_true", help="measure again with every phone in a namespace (root; clients)"
    )
    parser.add_argument(
        "--secure",
        action="store_true",
        help="measure again sealed, with the phones clients over tls/ and the router's access control",
    )
    parser.add_argument("--certs", help=argparse.SUPPRESS)
    parser.add_argument("--phone", help=argparse.SUPPRESS)
    parser.add_argument("--connect", help=argparse.SUPPRESS)
    parser.add_argument("--warmup", type=float, default=3.0, help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    return parser


def measure(args) -> None:
    if not args.latency_only:
        print("simulate, in-process virtual time (target: >= 200x real time, one core)", flush=True)
        for r in simulate_speed(args.games):
            print(
                f"  {r['scenario']:<37} {r['games']} games, {r['game_s']:7.1f} s of play in {r['wall_s']:6.2f} s: "
                f"{r['speedup']:6.1f}x real time",
                flush=True,
            )
    if not args.simulate_only:
        print(
            "fix -> guidance over Zenoh on loopback, 10 Hz per phone, ideal network (target: p99 < 20 ms at 10 phones)",
            flush=True,
        )
        runs = [(n, args.mode, False, False) for n in args.phones]
        runs += [(n, "client", True, False) for n in args.phones] if args.kernel else []
        runs += [(n, "client", False, True) for n in args.phones] if args.secure else []
        for n, mode, kernel, secure in runs:
            r = latency(n, args.duration, mode, kernel, secure)
            where = "namespaces, kernel network" if kernel else "loopback"
            where += ", sealed over tls/ with access control" if secure else ""
            print(
                f"  {n:3d} phones ({mode}s, {where}): {r['fixes']} fixes, {r['lost']} lost, "
                f"{r['unanswered']} unanswered; "
                f"latency p50 {r['p50_ms']:.2f} ms, p99 {r['p99_ms']:.2f} ms; "
                f"bare Zenoh echo p50 {r['echo_p50_ms']:.2f} ms, p99 {r['echo_p99_ms']:.2f} ms "
                f"(ratio p50 {r['p50_ms'] / r['echo_p50_ms']:.1f}x, p99 {r['p99_ms'] / r['echo_p99_ms']:.1f}x)",
                flush=True,
            )


if __name__ == "__main__":
    main()
