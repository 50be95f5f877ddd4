"""The bus shim against kernel mode: the same streams, the same profiles,
side by side.

    sudo python benchmarks/network_calibration.py                      # every profile, tcp and udp, 60 s each
    sudo python benchmarks/network_calibration.py --profiles 3g --seconds 120 --json calibration.json

One phone sends a fix (100 bytes) ten times a second to the ground station
and receives a guidance (2 KB) ten times a second, for ``--seconds``:

- in kernel mode, the phone is a Zenoh client in a network namespace behind
  the run's hub, the ground station a client of the router on this host's
  loopback (as ``bearcat run --network kernel`` places them); every packet of
  the phone's link is impaired by the profile, and TCP or Zenoh over UDP
  does what it does with them;
- through the shim, the same sends go through ``Shim.transmit`` in virtual
  time, as ``bearcat simulate`` and the peers of ``bearcat run`` apply it,
  for ten seeds (it is cheap, and the kernel run has noise enough).

For each profile, transport and direction it prints the delivered fraction,
the latency p50/p90/p99 and the share of messages that arrive in a burst
(within 2 ms of the message before them), kernel beside shim, and whether
the shim is within the targets: 20 % of kernel mode on p50, p90 and p99,
one point on the delivered fraction. Needs root and netfilterqueue (see
``bearcat.netem.kernel``).
"""

from __future__ import annotations

import argparse
import json
import struct
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

PROFILES = ("ideal", "wifi", "3g", "3g-degraded")
TRANSPORTS = ("tcp", "udp")
PERIOD = 0.1  # s between fixes, and between guidance messages
FIX_BYTES = 100
GUIDANCE_BYTES = 2000
BURST = 0.002  # s: an arrival this soon after the one before it is part of a burst
FIX_KEY = "bearcat/calibration/fix/phone"
GUIDANCE_KEY = "bearcat/calibration/guidance/phone"
SETTLE = 2.0  # s between the phone's subscription and its first fix
DRAIN = 15.0  # s the phone waits, after its last fix, for a quiet link: a stalled TCP stream delivers seconds late
SHIM_SEEDS = 10


def message(seq: int, size: int) -> bytes:
    """A payload of ``size`` bytes carrying its sequence number and when it was sent."""
    head = struct.pack("!Id", seq, time.time())
    return head + b"\0" * (size - len(head))


def read(payload: bytes) -> tuple[int, float]:
    return struct.unpack("!Id", payload[:12])


# ---------------------------------------------------------------------- kernel mode


def phone(args) -> None:
    """The phone process (in its namespace): fixes out, guidance in, arrivals to ``args.record``."""
    from bearcat.bus.zenoh_session import ZenohSession, best_effort_endpoint, config
    from bearcat.netem.profiles import load_profile

    lease_ms = round(1000 * load_profile(args.profile).link.lease)
    best_effort = None
    if args.transport == "udp":
        best_effort = config(listen=[], connect=[best_effort_endpoint(args.connect)], mode="client", lease_ms=lease_ms)
    arrivals = []
    reliable = config(listen=[], connect=[args.connect], mode="client", lease_ms=lease_ms)
    with ZenohSession("phone", reliable, best_effort=best_effort) as s:
        s.subscribe(GUIDANCE_KEY, lambda key, payload, sender: arrivals.append((*read(payload), time.time())))
        time.sleep(SETTLE)
        for seq in range(int(args.seconds / PERIOD)):
            s.put(FIX_KEY, message(seq, FIX_BYTES), reliable=False)
            time.sleep(PERIOD)
        last_fix = time.time()
        while time.time() - max([last_fix] + [a[-1] for a in arrivals[-1:]]) < DRAIN:
            time.sleep(0.1)
    Path(args.record).write_text(json.dumps(arrivals))


def through_the_kernel(profile: str, transport: str, seconds: float) -> dict:
    """The two streams through a kernel network under ``profile``; arrivals per direction."""
    from bearcat.bus.zenoh_session import ZenohSession, best_effort_endpoint, config
    from bearcat.netem.kernel.network import KernelNetwork
    from bearcat.netem.profiles import load_profile
    from bearcat.runtime.peer_commands import free_port

    port = free_port()
    lease_ms = round(1000 * load_profile(profile).link.lease)
    with tempfile.TemporaryDirectory() as work, KernelNetwork(profile, seed=1) as network:
        outside, loopback = f"tcp/{network.router}:{port}", f"tcp/127.0.0.1:{port}"
        listen = [outside, best_effort_endpoint(outside), loopback, best_effort_endpoint(loopback)]
        fixes = []
        with (
            ZenohSession("router", config(listen=listen, mode="router", lease_ms=lease_ms)),
            ZenohSession("gs", config(listen=[], connect=[loopback], mode="client", lease_ms=lease_ms)) as gs,
        ):
            phone_ready = threading.Event()  # a fix came: the phone has subscribed to its guidance

            def on_fix(key, payload, sender):
                fixes.append((*read(payload), time.time()))
                phone_ready.set()

            gs.subscribe(FIX_KEY, on_fix)
            record = Path(work) / "phone.json"
            command = [sys.executable, __file__, "--phone", "--connect", outside, "--transport", transport]
            command += ["--profile", profile]
            command += ["--seconds", str(seconds), "--record", str(record)]
            with open(Path(work) / "phone.log", "w") as log:
                child = network.spawn("phone", command, log_file=log)
            network.start(time.time())
            stop = threading.Event()

            def guide():
                while not phone_ready.wait(0.1):
                    if stop.is_set():
                        return
                for seq in range(int(seconds / PERIOD)):
                    if stop.is_set():
                        return
                    gs.put(GUIDANCE_KEY, message(seq, GUIDANCE_BYTES), reliable=False)
                    time.sleep(PERIOD)

            guiding = threading.Thread(target=guide)
            guiding.start()
            code = child.wait(timeout=seconds + 120)
            stop.set()
            guiding.join()
            if code != 0:
                raise RuntimeError(f"the phone exited with code {code}: {(Path(work) / 'phone.log').read_text()}")
            guidance = json.loads(record.read_text())
    sent = int(seconds / PERIOD)
    return {"fix": (sent, fixes), "guidance": (sent, [tuple(a) for a in guidance])}


# ---------------------------------------------------------------------- the shim


def through_the_shim(profile: str, transport: str, seconds: float, seeds: int = SHIM_SEEDS) -> dict:
    """The same streams through the shim in virtual time, once per seed: the
    shim costs nothing to run longer, so its figures carry less sampling
    noise than the one kernel run they are compared with."""
    from bearcat.netem.profiles import load_profile
    from bearcat.netem.shim import Shim

    count = int(seconds / PERIOD)
    directions = {"fix": ("phone", "gs", FIX_KEY, FIX_BYTES), "guidance": ("gs", "phone", GUIDANCE_KEY, GUIDANCE_BYTES)}
    sends = sorted(
        (SETTLE + k * PERIOD + (0.0 if name == "fix" else PERIOD / 2), name, k)
        for name in directions
        for k in range(count)
    )
    arrivals = {name: [] for name in directions}
    for seed in range(seeds):
        shim = Shim(load_profile(profile).link, seed=seed, transport=transport)
        for t, name, seq in sends:
            sender, receiver, key, size = directions[name]
            for d in shim.transmit(sender, receiver, key, b"\0" * size, t):
                arrivals[name].append((seed * count + seq, t, d.at))
    return {name: (seeds * count, arrivals[name], seeds) for name in directions}


# ---------------------------------------------------------------------- the table


def measure(sent: int, arrivals: list, runs: int = 1) -> dict:
    """Delivered fraction with its 95 % interval, latency quantiles (ms) and
    burst share of one direction's arrivals (first copies). Losses come in
    bursts, so the interval is from batch means (ten batches of the stream),
    not from a binomial count."""
    first = {}
    for seq, t_sent, t_arrived in arrivals:
        first.setdefault(seq, (t_sent, t_arrived))
    latency = np.array([a - s for s, a in first.values()]) * 1000
    gaps = []
    for run in range(runs):  # the shim's seeds each make a stream of their own
        order = np.sort([a for seq, (_, a) in first.items() if seq * runs // sent == run])
        gaps.extend(np.diff(order))
    bursts = float(np.mean(np.array(gaps) < BURST)) if gaps else 0.0
    p50, p90, p99 = np.percentile(latency, [50, 90, 99]) if latency.size else (np.nan,) * 3
    batches = np.array_split(np.isin(np.arange(sent), list(first)), 10)
    spread = 1.96 * np.std([b.mean() for b in batches], ddof=1) / np.sqrt(len(batches))
    return {"delivered": len(first) / sent, "interval": spread, "p50": p50, "p90": p90, "p99": p99, "bursts": bursts}


def within_targets(kernel: dict, shim: dict) -> bool:
    """20 % of kernel mode on each quantile (2 ms at the least: the hub and the
    stack add about a millisecond the model leaves out), one point on the
    delivered fraction."""
    close = all(abs(shim[q] - kernel[q]) <= max(0.2 * kernel[q], 2.0) for q in ("p50", "p90", "p99"))
    return close and abs(shim["delivered"] - kernel["delivered"]) <= 0.01


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--profiles", nargs="+", default=PROFILES)
    parser.add_argument("--transports", nargs="+", default=TRANSPORTS, choices=TRANSPORTS)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--json", type=Path, help="write every figure here")
    parser.add_argument("--phone", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--connect", help=argparse.SUPPRESS)
    parser.add_argument("--transport", help=argparse.SUPPRESS)
    parser.add_argument("--record", help=argparse.SUPPRESS)
    parser.add_argument("--profile", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.phone:
        phone(args)
        return
    rows = []
    print(
        f"{'profile':<12} {'transport':<9} {'stream':<9} {'delivered %':>16} {'p50 ms':>15} {'p90 ms':>15} "
        f"{'p99 ms':>15} {'bursts %':>13}  shim within targets",
        flush=True,
    )
    print(f"{'':<32} {'kernel / shim':>16} {'kernel / shim':>15} {'kernel / shim':>15} {'kernel / shim':>15}")
    for profile in args.profiles:
        for transport in args.transports:
            kernel = through_the_kernel(profile, transport, args.seconds)
            shim = through_the_shim(profile, transport, args.seconds)
            for stream in ("fix", "guidance"):
                k, s = measure(*kernel[stream]), measure(*shim[stream])
                rows.append({"profile": profile, "transport": transport, "stream": stream, "kernel": k, "shim": s})
                print(
                    f"{profile:<12} {transport:<9} {stream:<9} "
                    f"{100 * k['delivered']:>5.1f}±{100 * k['interval']:<3.1f} / {100 * s['delivered']:<5.1f} "
                    + " ".join(f"{k[q]:>6.0f} / {s[q]:<6.0f}" for q in ("p50", "p90", "p99"))
                    + f" {100 * k['bursts']:>5.1f} / {100 * s['bursts']:<5.1f}  "
                    + ("yes" if within_targets(k, s) else "no"),
                    flush=True,
                )
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
