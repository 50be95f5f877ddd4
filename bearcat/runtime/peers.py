"""Where the peer processes of a live run start and how they reach the router.

``LocalPeers``: every peer a child process on this host's network, joining
the launcher's router over the loopback; the peers' own netem shims impair
the messages. ``KernelPeers``: each peer but the ground station in a network
namespace of its own behind the run's kernel network, which impairs the
real packets (``netem.kernel``); the ground station, on the launcher's
laptop in the field, stays on the loopback.

Either way every child dies with the launcher (the parent-death signal), so
a launcher killed with SIGKILL leaves no peer running; the signal is
SIGTERM, on which a peer says in its log that the launcher died, and ends.
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path

from bearcat.bus.zenoh_session import best_effort_endpoint
from bearcat.netem.kernel.commands import die_saying_so

NETWORKS = ("shim", "kernel")


class LocalPeers:
    """Peers on this host's network; the router listens on the loopback at
    ``port``, over ``tls/`` alone when ``secure``."""

    impairs = "shim"  # what impairs a peer's messages, as its spec says it (``PeerSpec.network``)

    def __init__(self, port: int, *, secure: bool = False) -> None:
        self.secure = secure
        self.loopback = f"{'tls' if secure else 'tcp'}/127.0.0.1:{port}"

    def __enter__(self) -> LocalPeers:
        return self

    def __exit__(self, *_exc) -> None:
        pass

    @property
    def listen(self) -> list[str]:
        """The router's endpoints: tcp/ for everything, udp/ for best-effort
        traffic that asks for it; tls/ alone on a secure run."""
        return [self.loopback] if self.secure else [self.loopback, best_effort_endpoint(self.loopback)]

    @property
    def hosts(self) -> tuple[str, ...]:
        """The addresses peers reach the router at, which its certificate must name."""
        return ("127.0.0.1",)

    def start(
        self,
        name: str,
        command: Callable[[str], list[str]],
        log: Path,
        *,
        colocated: bool = False,
        again: bool = False,
        beside: subprocess.Popen | None = None,
    ) -> subprocess.Popen:
        """Start peer ``name`` running ``command(endpoint)``, its output in ``log``
        (after what it wrote before, when it starts ``again``); a ``colocated``
        peer shares the router's machine (the ground station); a peer
        ``beside`` a running process shares its network (a UAV's peer started
        again, beside the vehicle it flies over that network's loopback)."""
        return _child(command(self.loopback), log, again)

    def start_vehicle(self, flyer: subprocess.Popen, command: list[str], log: Path) -> subprocess.Popen:
        """Start the vehicle emulator ``flyer``'s UAV peer flies, where that peer reaches it on its loopback."""
        return _child(command, log)

    def game_started(self, t: float) -> None:
        """The game started at Unix time ``t``."""

    def describe(self, netem: str) -> str:
        """What impairs the run's traffic, for the launcher to say."""
        return f"network: on this host; each peer's shim impairs the messages it receives by profile {netem}"

    def host_side(self) -> dict | None:
        """What the run adds to the host's network while it runs (None: nothing)."""
        return None

    def own_processes(self) -> dict[str, int]:
        """The processes the network itself runs for the run, by name: their numbers."""
        return {}


class KernelPeers(LocalPeers):
    """Peers in namespaces behind a kernel network impairing packets with profile ``netem``."""

    impairs = "kernel"

    def __init__(self, port: int, netem: str, seed: int, report: Path, *, secure: bool = False) -> None:
        from bearcat.netem.kernel.network import KernelNetwork

        super().__init__(port, secure=secure)
        self.port = port
        self.network = KernelNetwork(netem, seed, report=report)

    def __enter__(self) -> KernelPeers:
        self.network.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self.network.__exit__(*exc)

    @property
    def outside(self) -> str:
        """The router's endpoint on the kernel network."""
        return f"{'tls' if self.secure else 'tcp'}/{self.network.router}:{self.port}"

    @property
    def listen(self) -> list[str]:
        if self.secure:
            return [*super().listen, self.outside]
        return [*super().listen, self.outside, best_effort_endpoint(self.outside)]

    @property
    def hosts(self) -> tuple[str, ...]:
        return (*super().hosts, self.network.router)

    def start(self, name, command, log, *, colocated=False, again=False, beside=None) -> subprocess.Popen:
        if colocated:
            return super().start(name, command, log, again=again)
        with open(log, "a" if again else "w") as output:
            if beside is not None and beside.poll() is None:
                return self.network.enter(beside, command(self.outside), log_file=output)
            return self.network.spawn(name, command(self.outside), log_file=output)

    def start_vehicle(self, flyer, command, log) -> subprocess.Popen:
        with open(log, "w") as output:
            return self.network.enter(flyer, command, log_file=output)

    def game_started(self, t: float) -> None:
        self.network.start(t)

    def describe(self, netem: str) -> str:
        return self.network.describe()

    def host_side(self) -> dict | None:
        return self.network.host_side

    def own_processes(self) -> dict[str, int]:
        assert self.network.hub is not None, "the hub runs once the network is entered"
        return {"hub": self.network.hub.pid}


def _child(command: list[str], log: Path, again: bool = False) -> subprocess.Popen:
    # The child keeps its own copy of the log's descriptor; ours closes at once.
    with open(log, "a" if again else "w") as output:
        return subprocess.Popen(
            command, stdout=output, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, preexec_fn=die_saying_so
        )
