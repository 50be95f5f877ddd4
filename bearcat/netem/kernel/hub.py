"""The hub: the process that lives in the run's hub namespace and impairs
every packet that crosses it.

The launcher starts it with ``unshare --net`` and talks to it in JSON lines
on its standard input; it answers each line on its standard output:

- ``{"link": NAME, "iface": IF, "queues": [UP, DOWN]}``: the peer ``NAME``
  is attached on ``IF``; its packets toward the router are queued on
  ``UP``, those toward it on ``DOWN``, each direction impaired on its own;
- ``{"start": T}``: the game started at Unix time ``T``; outage windows
  count from it;
- ``{"cut": [NAME, ...]}``: those peers' links drop every packet (a
  partition or an outage), until ``{"heal": [NAME, ...]}`` (``null``: every
  link), which also ends a degradation;
- ``{"degrade": [NAME, ...], "profile": P}``: those links follow profile ``P``.

The end of its standard input (the launcher closed it, or died) ends the
hub, which writes what it did per link to the file given with ``--report``.
Nothing else does: a Ctrl-C at the terminal reaches every process of the
launcher's group, and the hub must go on carrying packets while the
launcher stops the peers, who say goodbye through it. A hub gone first left
their connections hanging: the peers had to be killed, and the router's
half-open sockets held the host's end of the link for a while after the
run.

Each packet arrives through iptables NFQUEUE; the hub draws its fate
(``scheduler``), holds it until its time and accepts it, drops it, or for a
duplicate accepts it and sends a copy through a raw socket. The queues are
read without blocking from one loop that also keeps the timer of held
packets, so a packet leaves within a millisecond or so of its time. The
hub runs ahead of ordinary processes (round-robin real-time scheduling, at
a low real-time priority), so that a laptop busy with a study or the game's
own peers delays a packet by its profile, not by the scheduler.
"""

from __future__ import annotations

import argparse
import functools
import heapq
import itertools
import json
import os
import selectors
import signal
import socket
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bearcat.netem.kernel.commands import KernelError, run
from bearcat.netem.kernel.scheduler import Direction
from bearcat.netem.link import LinkState, link_rng
from bearcat.netem.profiles import ProfileError, load_profile

if TYPE_CHECKING:
    from netfilterqueue import NetfilterQueue

QUEUE_LENGTH = 65536
"""Packets one queue may hold in the kernel before it drops: seconds of a busy link's traffic."""
RT_PRIORITY = 10  # of 1-99: above ordinary processes, below the kernel's own real-time threads


class Hub:
    """The hub's state: the directions it impairs, the packets it holds, the game's start."""

    def __init__(self, profile: str, seed: int, profiles: Path | None = None) -> None:
        self.model = load_profile(profile, profiles).link
        self.seed = seed
        self.epoch: float | None = None
        self.directions: dict[int, Direction] = {}
        self.links: dict[str, tuple[Direction, Direction]] = {}
        self.queues: list[NetfilterQueue] = []
        self.held: list = []  # (release time, order, packet, is a copy)
        self.order = itertools.count()
        self.selector = selectors.DefaultSelector()
        self.raw = socket.socket(socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_RAW)

    def attach(self, name: str, iface: str, up: int, down: int) -> None:
        """Queue ``name``'s packets on ``up`` (toward the router) and ``down`` (toward it)."""
        from netfilterqueue import NetfilterQueue

        pair = []
        for queue, match, sender, receiver in ((up, "-i", name, "hub"), (down, "-o", "hub", name)):
            state = LinkState(self.model, link_rng(self.seed, sender, receiver))
            self.directions[queue] = direction = Direction(f"{sender} -> {receiver}", state)
            pair.append(direction)
            nfq = NetfilterQueue()
            nfq.bind(queue, functools.partial(self._arrived, direction), max_len=QUEUE_LENGTH)
            self.queues.append(nfq)
            self.selector.register(nfq.get_fd(), selectors.EVENT_READ, nfq)
            run("iptables", "-t", "mangle", "-A", "FORWARD", match, iface, "-j", "NFQUEUE", "--queue-num", str(queue))
        self.links[name] = (pair[0], pair[1])

    def directions_of(self, names) -> list[Direction]:
        """Both directions of each named link (names of peers without one are passed over)."""
        chosen = self.links if names is None else {n: self.links[n] for n in names if n in self.links}
        return [d for pair in chosen.values() for d in pair]

    def cut(self, names) -> None:
        for d in self.directions_of(names):
            d.cut = True

    def heal(self, names) -> None:
        for d in self.directions_of(names):
            d.cut = False
            if d.own is not None:
                d.state, d.own = d.own, None

    def degrade(self, names, profile: str) -> None:
        model = load_profile(profile).link
        for d in self.directions_of(names):
            d.own = d.own or d.state
            sender, _, receiver = d.name.partition(" -> ")
            d.state = LinkState(model, link_rng(self.seed + 1, sender, receiver))

    def _arrived(self, direction: Direction, packet) -> None:
        now = time.time()
        game_time = None if self.epoch is None else now - self.epoch
        releases = direction.schedule(now, packet.get_payload_len(), game_time)
        if not releases:
            packet.drop()
            return
        packet.retain()
        for k, at in enumerate(releases):
            heapq.heappush(self.held, (at, next(self.order), packet, k > 0))

    def release_due(self) -> float | None:
        """Let go of the packets whose time has come; seconds until the next one (None: none held)."""
        now = time.time()
        while self.held and self.held[0][0] <= now:
            _, _, packet, copy = heapq.heappop(self.held)
            if copy:
                payload = packet.get_payload()
                destination = socket.inet_ntoa(payload[16:20])
                try:
                    self.raw.sendto(payload, (destination, 0))
                except OSError:
                    pass  # a duplicate that cannot be sent is a duplicate that did not happen
            else:
                packet.accept()
        return None if not self.held else max(self.held[0][0] - now, 0.0)

    def report(self) -> dict:
        links = {}
        for direction in self.directions.values():
            delays = np.array(direction.delays) if direction.delays else np.zeros(0)
            links[direction.name] = {
                "counts": direction.counts,
                "delay_s": {
                    q: round(float(np.percentile(delays, p)), 6) if delays.size else None
                    for q, p in (("p50", 50), ("p90", 90), ("p99", 99))
                },
            }
        return links


def serve(hub: Hub, commands, answer) -> None:
    """Read ``commands`` and packets until the commands end."""
    hub.selector.register(commands.fileno(), selectors.EVENT_READ, None)
    buffered = b""
    while True:
        timeout = hub.release_due()
        for key, _ in hub.selector.select(timeout):
            if key.data is not None:
                key.data.run(block=False)
                continue
            chunk = os.read(commands.fileno(), 65536)
            if not chunk:
                return
            buffered += chunk
            while b"\n" in buffered:
                line, buffered = buffered.split(b"\n", 1)
                answer(obey(hub, json.loads(line)))


def obey(hub: Hub, command: dict) -> dict:
    try:
        if "link" in command:
            up, down = command["queues"]
            hub.attach(command["link"], command["iface"], int(up), int(down))
            return {"ok": f"link {command['link']}"}
        if "start" in command:
            hub.epoch = float(command["start"])
            return {"ok": "start"}
        if "cut" in command:
            hub.cut(command["cut"])
            return {"ok": "cut"}
        if "heal" in command:
            hub.heal(command["heal"])
            return {"ok": "heal"}
        if "degrade" in command:
            hub.degrade(command["degrade"], command["profile"])
            return {"ok": "degrade"}
        return {"error": f"unknown command {command!r}"}
    except (KernelError, OSError, ValueError, KeyError, ProfileError) as exc:
        return {"error": str(exc)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bearcat.netem.kernel.hub")
    parser.add_argument("--profile", required=True)
    parser.add_argument("--profiles", type=Path, help="the profile file (default: the built-in one)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--report", type=Path)
    args = parser.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _ahead_of_the_rest()

    def answer(reply: dict) -> None:
        sys.stdout.write(json.dumps(reply) + "\n")
        sys.stdout.flush()

    try:
        hub = Hub(args.profile, args.seed, args.profiles)
        Path("/proc/sys/net/ipv4/ip_forward").write_text("1\n")
        run("ip", "link", "set", "lo", "up")
    except (KernelError, OSError, ImportError, ProfileError) as exc:
        answer({"error": f"the hub could not start: {exc}"})
        return 1
    answer({"ok": "ready", "netem": _has_netem()})
    try:
        serve(hub, sys.stdin.buffer, answer)
    finally:
        if args.report is not None:
            args.report.write_text(json.dumps(hub.report(), indent=2) + "\n")
    return 0


def _ahead_of_the_rest() -> None:
    """Run before every ordinary process when one is ready; the kernel's
    real-time throttling still leaves them a share of each second. Where
    the policy cannot be had, the hub runs as an ordinary process."""
    try:
        # The commands it runs (ip, tc) start as ordinary processes again.
        os.sched_setscheduler(0, os.SCHED_RR | os.SCHED_RESET_ON_FORK, os.sched_param(RT_PRIORITY))
    except (AttributeError, OSError):
        pass


def _has_netem() -> bool:
    """Whether this kernel has the netem qdisc (tried on the hub's own loopback)."""
    try:
        run("tc", "qdisc", "add", "dev", "lo", "root", "netem", "delay", "1ms")
    except KernelError:
        return False
    run("tc", "qdisc", "del", "dev", "lo", "root")
    return True


if __name__ == "__main__":
    sys.exit(main())
