"""The star of namespaces of one live run.

::

    launcher (router)  --  hub namespace  --  attacker's namespace
      this host's            routes and       --  defender's namespace
      namespace              impairs          --  ...

The launcher's router stays in this host's namespace. The hub namespace
routes between it and each peer's namespace, one veth pair per peer, and
impairs each peer's link in both directions (``hub``). Addresses come from
198.18.0.0/15, the block set aside for network benchmarks (RFC 2544): one
/24 per run, a /30 per link.

Every process is started with ``unshare --net --fork --kill-child`` (the
hub, each peer) or ``nsenter`` into a peer's namespace (its vehicle), and
with the parent-death signal set, so it dies with the launcher; a namespace
lives only while a process is in it, and veth pairs and iptables rules die
with their namespaces. Nothing is named in the host but the veth end and
the route to the run's /24, which go when the hub's namespace does.
"""

from __future__ import annotations

import contextlib
import fcntl
import ipaddress
import json
import logging
import os
import select
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

from bearcat.netem.kernel.commands import KernelError, await_namespace, die_saying_so, die_with_parent, inside, run

log = logging.getLogger(__name__)

BLOCK = ipaddress.IPv4Network("198.18.0.0/15")
MAX_PEERS = 63  # /30 links in a /24, the first one the launcher's
LOCK = Path("/run/lock/bearcat-network.lock")
CAP_NET_ADMIN, CAP_SYS_ADMIN = 12, 21
STARTUP = 10.0  # s for a namespace to appear or the hub to answer
TOOLS = ("ip", "unshare", "nsenter", "iptables", "tc")


def _capable(*capabilities: int) -> bool:
    """Whether this process holds every one of ``capabilities`` (numbers of linux/capability.h)."""
    status = Path("/proc/self/status").read_text()
    effective = int(next(line.split()[1] for line in status.splitlines() if line.startswith("CapEff:")), 16)
    return all(effective >> c & 1 for c in capabilities)


def missing() -> str | None:
    """What this machine lacks for kernel mode, as one sentence, or None."""
    if not _capable(CAP_SYS_ADMIN, CAP_NET_ADMIN):
        return (
            "--network kernel needs root, or the capabilities CAP_SYS_ADMIN and CAP_NET_ADMIN (for namespaces, "
            "veth pairs and iptables rules); run as root, or leave out --network kernel to impair messages in "
            "the peers"
        )
    absent = [tool for tool in TOOLS if shutil.which(tool) is None]
    if absent:
        return (
            f"--network kernel needs {', '.join(absent)}: on Debian or Ubuntu, apt-get install iproute2 "
            "util-linux iptables"
        )
    try:
        import netfilterqueue  # noqa: F401
    except ImportError:
        return (
            "--network kernel needs the netfilterqueue package: apt-get install libnetfilter-queue-dev, then "
            "pip install 'bearcat[kernel]'"
        )
    return None


class KernelNetwork:
    """The run's namespaces: ``with KernelNetwork(profile, seed, report=PATH) as net:``,
    ``profile`` a name in the built-in profiles or in the file ``profiles``.

    ``router`` is the address the launcher's router listens on for the
    peers; ``spawn`` starts a peer in a namespace of its own, ``enter``
    starts a process in a peer's namespace, ``start`` tells the hub the
    game began. On the way out the hub ends and its namespace, the links and
    every rule go with it."""

    def __init__(self, profile: str, seed: int, *, report: Path | None = None, profiles: Path | None = None) -> None:
        why = missing()
        if why is not None:
            raise KernelError(why)
        self.profile = profile
        self.seed = seed
        self.report = report
        self.profiles = profiles
        self.hub: subprocess.Popen[bytes] | None = None
        self.netem = False  # whether this kernel has the netem qdisc (the hub impairs packets either way)
        self._links = 0
        self._subnet: ipaddress.IPv4Network | None = None
        self._veth: str | None = None  # the host's end of the link to the hub
        self._ifindex: int | None = None  # its number, which no later link of the same name shares
        # Each peer's namespace held open until the end: a peer that exits
        # would otherwise take its end of the link with it, and the router's
        # goodbye over a delayed link would wait for an answer that never comes.
        self._held: list[int] = []
        self._asking = threading.Lock()  # the launcher's fault thread asks too

    # ------------------------------------------------------------------ the run

    def __enter__(self) -> KernelNetwork:
        try:
            self._build()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *_exc) -> None:
        self.close()

    @property
    def host_side(self) -> dict:
        """What this network adds to the host's own namespace while it runs:
        the link to the hub (its name, which the next network takes once this
        one is gone, and its interface number, which no later link shares)
        and the route through it (all else is inside the namespaces and goes
        with them)."""
        return {
            "link": self._veth,
            "ifindex": self._ifindex,
            "route": None if self._subnet is None else str(self._subnet),
        }

    def describe(self) -> str:
        """Which machinery impairs the packets, and why not netem where the kernel has it."""
        kernel = (
            "this kernel has the netem qdisc, but netem has no radio promotion after idle, no outage windows"
            " counted from the start of the game and not the shim's draws, so the hub applies the profile"
            if self.netem
            else "this kernel has no netem qdisc, so the hub applies the profile"
        )
        return (
            f"network: kernel, {self._subnet}; each peer in a namespace of its own, its packets impaired by"
            f" profile {self.profile} in an NFQUEUE hub ({kernel})"
        )

    @property
    def router(self) -> str:
        return str(self._address(0, 1))

    def spawn(self, name: str, argv: list[str], *, log_file, impaired: bool = True) -> subprocess.Popen:
        """Start ``argv`` as peer ``name`` in a namespace of its own, linked
        to the hub (and impaired there unless ``impaired`` is False); it runs
        once its network is up."""
        assert self.hub is not None, "a peer is spawned inside the with block"
        k = self._links = self._links + 1
        if k > MAX_PEERS:
            raise KernelError(f"a kernel network holds at most {MAX_PEERS} peers")
        # The peer is unshare's child: SIGTERM when unshare dies with the launcher, so it says why it ends.
        gate = [
            *("unshare", "--net", "--fork", "--kill-child=SIGTERM"),
            *("sh", "-c", 'read -r _ && exec "$@"', "gate", *argv),
        ]
        child = subprocess.Popen(
            gate, stdin=subprocess.PIPE, stdout=log_file, stderr=subprocess.STDOUT, preexec_fn=die_with_parent
        )
        try:
            await_namespace(child.pid, f"peer {name}", STARTUP)
            self._held.append(os.open(f"/proc/{child.pid}/ns/net", os.O_RDONLY))
            hub_side, peer_side = self._address(k, 1), self._address(k, 2)
            inside(
                self.hub.pid,
                "ip",
                "link",
                "add",
                f"p{k}",
                "type",
                "veth",
                "peer",
                "name",
                "eth0",
                "netns",
                str(child.pid),
            )
            inside(self.hub.pid, "ip", "addr", "add", f"{hub_side}/30", "dev", f"p{k}")
            inside(self.hub.pid, "ip", "link", "set", f"p{k}", "up")
            for command in (
                ("ip", "link", "set", "lo", "up"),
                ("ip", "addr", "add", f"{peer_side}/30", "dev", "eth0"),
                ("ip", "link", "set", "eth0", "up"),
                ("ip", "route", "add", "default", "via", str(hub_side)),
            ):
                inside(child.pid, *command)
            if impaired:
                self._ask({"link": name, "iface": f"p{k}", "queues": [2 * k, 2 * k + 1]})
            assert child.stdin is not None  # a pipe
            child.stdin.write(b"go\n")
            child.stdin.close()
        except BaseException:
            child.kill()
            child.wait()
            raise
        return child

    def enter(self, peer: subprocess.Popen, argv: list[str], *, log_file) -> subprocess.Popen:
        """Start ``argv`` in ``peer``'s namespace (a UAV's vehicle, on its loopback)."""
        return subprocess.Popen(
            ["nsenter", "-t", str(peer.pid), "-n", *argv],
            stdout=log_file,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            preexec_fn=die_saying_so,
        )

    def start(self, t: float) -> None:
        """The game started at Unix time ``t``: outage windows count from it."""
        self._ask({"start": t})

    def cut(self, names) -> None:
        """Drop every packet of the named peers' links (a partition, an outage)."""
        self._ask({"cut": list(names)})

    def heal(self, names=None) -> None:
        """End the cuts and degradations of the named links (None: of every link)."""
        self._ask({"heal": None if names is None else list(names)})

    def degrade(self, names, profile: str) -> None:
        """The named links follow ``profile`` until healed."""
        self._ask({"degrade": list(names), "profile": profile})

    def close(self) -> None:
        while self._held:
            os.close(self._held.pop())
        if self.hub is None:
            return
        hub, self.hub = self.hub, None
        try:
            assert hub.stdin is not None  # a pipe
            hub.stdin.close()
            hub.wait(timeout=STARTUP)
        except (OSError, subprocess.TimeoutExpired):
            hub.kill()
            hub.wait()
        if self._veth is not None:
            # The kernel tears a dead namespace down in the background: its
            # end of the link (and the route through it) would outlive this
            # call by a moment. Deleting the host's end is immediate, unless
            # that teardown has begun, when the delete is refused and the
            # link lingers: wait for it to go, so nothing outlives the run.
            veth, self._veth = self._veth, None
            with contextlib.suppress(KernelError):
                run("ip", "link", "del", veth)
            end = time.monotonic() + STARTUP
            while Path(f"/sys/class/net/{veth}").exists() and time.monotonic() < end:
                time.sleep(0.05)
                with contextlib.suppress(KernelError):
                    run("ip", "link", "del", veth)
            if Path(f"/sys/class/net/{veth}").exists():
                log.warning("link %s is still there %g s after the run", veth, STARTUP)

    # ------------------------------------------------------------------ building

    def _build(self) -> None:
        LOCK.parent.mkdir(parents=True, exist_ok=True)
        with open(LOCK, "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # two runs must not take the same /24
            self._subnet = self._free_subnet()
            command = [sys.executable, "-m", "bearcat.netem.kernel.hub", "--profile", self.profile]
            command += ["--seed", str(self.seed)]
            if self.report is not None:
                command += ["--report", str(self.report)]
            if self.profiles is not None:
                command += ["--profiles", str(self.profiles)]
            self.hub = subprocess.Popen(
                ["unshare", "--net", "--fork", "--kill-child", *command],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                preexec_fn=die_with_parent,
            )
            ready = self._reply()
            self.netem = bool(ready.get("netem"))
            host, hub = self._address(0, 1), self._address(0, 2)
            veth = f"bcat{list(BLOCK.subnets(new_prefix=24)).index(self._subnet)}"
            self._veth = veth
            run("ip", "link", "add", veth, "type", "veth", "peer", "name", "up0", "netns", str(self.hub.pid))
            self._ifindex = int(Path(f"/sys/class/net/{veth}/ifindex").read_text())
            run("ip", "addr", "add", f"{host}/30", "dev", veth)
            run("ip", "link", "set", veth, "up")
            inside(self.hub.pid, "ip", "addr", "add", f"{hub}/30", "dev", "up0")
            inside(self.hub.pid, "ip", "link", "set", "up0", "up")
            inside(self.hub.pid, "ip", "route", "add", "default", "via", str(host))
            run("ip", "route", "add", str(self._subnet), "via", str(hub))

    def _free_subnet(self) -> ipaddress.IPv4Network:
        routes = json.loads(run("ip", "-j", "-4", "route", "show") or "[]")
        taken = [ipaddress.ip_network(r["dst"], strict=False) for r in routes if r.get("dst", "default") != "default"]
        for subnet in BLOCK.subnets(new_prefix=24):
            if not any(subnet.overlaps(t) for t in taken):
                return subnet
        raise KernelError("every /24 of 198.18.0.0/15 is routed already: too many kernel networks on this host")

    def _address(self, link: int, host: int) -> ipaddress.IPv4Address:
        assert self._subnet is not None, "addresses are taken once the subnet is"
        return self._subnet.network_address + 4 * link + host

    def _ask(self, command: dict) -> dict:
        assert self.hub is not None and self.hub.stdin is not None, "the hub runs, its input a pipe"
        with self._asking:
            self.hub.stdin.write((json.dumps(command) + "\n").encode())
            self.hub.stdin.flush()
            return self._reply()

    def _reply(self) -> dict:
        assert self.hub is not None and self.hub.stdout is not None, "the hub runs, its output a pipe"
        ready, _, _ = select.select([self.hub.stdout], [], [], STARTUP)
        if not ready:
            raise KernelError(f"the network hub did not answer within {STARTUP:g} s")
        line = self.hub.stdout.readline()
        if not line:
            raise KernelError(f"the network hub exited with code {self.hub.wait()} before it answered")
        reply = json.loads(line)
        if "error" in reply:
            raise KernelError(reply["error"])
        return reply
