"""Computers on a field network, stood in for by network namespaces.

``with Machines("laptop", "companion", ...) as net:`` makes one network
namespace per name, each with its loopback up, and joins the first (the
ground station's laptop) to each of the others by a veth pair of its own,
with addresses from 198.19.255.0/24: the last /24 of the block kernel mode
takes its networks from, in namespaces of their own, so neither sees the
other. Every other machine routes through the laptop, so each reaches
every address of the laptop (``net.address("laptop")`` is its end of the
first link). ``net.start(name, argv)`` runs a program on a machine.

Each namespace lives while a process is in it: a holder (``sleep``, which
``unshare --net`` becomes once the namespace is made), and whatever runs
there. Everything is started with the
parent-death signal, and on the way out every process started is killed
and waited for, so the namespaces, their links and addresses go with them
and nothing is left in this host's own namespace, which is never touched.
"""

from __future__ import annotations

import subprocess

from bearcat.netem.kernel.commands import await_namespace, die_with_parent, inside
from bearcat.netem.kernel.network import BLOCK

SUBNET = list(BLOCK.subnets(new_prefix=24))[-1]
STARTUP = 10.0  # s for a namespace to appear


class Machines:
    def __init__(self, *names: str) -> None:
        self.names = names
        self.holders: dict[str, subprocess.Popen] = {}
        self.started: list[subprocess.Popen] = []
        self._addresses: dict[str, str] = {}

    def __enter__(self) -> Machines:
        try:
            for name in self.names:
                holder = subprocess.Popen(["unshare", "--net", "sleep", "3600"], preexec_fn=die_with_parent)
                self.holders[name] = holder
                await_namespace(holder.pid, f"machine {name}", STARTUP)
                inside(holder.pid, "ip", "link", "set", "lo", "up")
            laptop, *others = self.names
            for k, name in enumerate(others):
                near, far = (SUBNET.network_address + 4 * k + host for host in (1, 2))
                pair = ("ip", "link", "add", f"to{k}", "type", "veth", "peer", "name", "eth0")
                inside(self.pid(laptop), *pair, "netns", str(self.pid(name)))
                inside(self.pid(laptop), "ip", "addr", "add", f"{near}/30", "dev", f"to{k}")
                inside(self.pid(laptop), "ip", "link", "set", f"to{k}", "up")
                inside(self.pid(name), "ip", "addr", "add", f"{far}/30", "dev", "eth0")
                inside(self.pid(name), "ip", "link", "set", "eth0", "up")
                inside(self.pid(name), "ip", "route", "add", "default", "via", str(near))
                self._addresses.setdefault(laptop, str(near))
                self._addresses[name] = str(far)
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *_exc) -> None:
        self.close()

    def pid(self, name: str) -> int:
        return self.holders[name].pid

    def address(self, name: str) -> str:
        """The machine's address (the laptop's: its end of the first link)."""
        return self._addresses[name]

    def start(self, name: str, argv: list[str], **popen) -> subprocess.Popen:
        """Run ``argv`` on machine ``name``; it is killed on the way out if still running."""
        process = subprocess.Popen(
            ["nsenter", "-t", str(self.pid(name)), "-n", *argv], preexec_fn=die_with_parent, **popen
        )
        self.started.append(process)
        return process

    def processes(self) -> list[subprocess.Popen]:
        """Every process started here, holders included."""
        return [*self.started, *self.holders.values()]

    def close(self) -> None:
        for process in self.processes():
            if process.poll() is None:
                process.kill()
        for process in self.processes():
            process.wait()
