"""Kernel mode: real packets through network namespaces, impaired by the hub.

The link carries the profile's delay and loss (measured on a stream of UDP
probes, independently of the hub's own report), a live game in kernel mode
ends with a verdict, and a run ended by Ctrl-C, by a peer's death or by a
SIGKILL of its launcher leaves no process, interface or route behind. These tests need root and netfilterqueue; they
skip with the reason otherwise (CI runs them as root).
"""

import ipaddress
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bearcat.netem.kernel.network import KernelNetwork, missing
from bearcat.suites.checker import check_run

needs_kernel = pytest.mark.skipif(missing() is not None, reason=str(missing()))
# One worker of a parallel session runs these in turn: they look for what
# any kernel network left in the host's namespace.
pytestmark = pytest.mark.xdist_group("kernel")

PROBES = 2000
PROFILES = """
[probe]
description = "a fixed delay and a known loss, to measure"
[probe.link]
delay = 0.1
loss = 0.05
"""
SO_TIMESTAMPNS = 35  # Linux's, which Python's socket module does not name (its control message has the same number)
SENDER = """
import socket, struct, sys, time
host, port, count = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
for k in range(count):
    s.sendto(struct.pack("!Id", k, time.time()), (host, port))
    time.sleep(0.005)
"""


def leftovers(added: dict) -> dict:
    """What of ``added`` (a kernel network's ``host_side``: its link and its
    route) is still in this host's namespace. The link is known by its
    interface number: a kernel run in another test worker takes the same
    name and subnet as soon as this one's are free."""
    links = json.loads(subprocess.run(["ip", "-j", "link"], capture_output=True, text=True).stdout)
    mine = [link["ifname"] for link in links if (link["ifname"], link["ifindex"]) == (added["link"], added["ifindex"])]
    routes = json.loads(subprocess.run(["ip", "-j", "-4", "route"], capture_output=True, text=True).stdout)
    subnet = ipaddress.ip_network(added["route"])
    through = [r["dst"] for r in routes if r.get("dev") in mine and r.get("dst", "default") != "default"]
    return {
        "interfaces": mine,
        "routes": [dst for dst in through if ipaddress.ip_network(dst, strict=False).subnet_of(subnet)],
    }


def added_by(tmp_path: Path) -> dict:
    """The link and route the run in ``tmp_path`` added to the host (``endpoint.json``)."""
    return json.loads((tmp_path / "run" / "endpoint.json").read_text())["network"]


NOTHING = {"interfaces": [], "routes": []}


@needs_kernel
def test_a_link_delays_and_loses_packets_as_its_profile_says(tmp_path):
    profiles = tmp_path / "profiles.toml"
    profiles.write_text(PROFILES)
    with (
        KernelNetwork("probe", seed=1, profiles=profiles, report=tmp_path / "network.json") as network,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver,
    ):
        added = network.host_side
        receiver.bind((network.router, 0))
        receiver.settimeout(2.0)
        # Each datagram's arrival as the kernel stamped it, not as this (perhaps busy) process read it.
        receiver.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        port = receiver.getsockname()[1]
        with open(tmp_path / "sender.log", "w") as log:
            sender = network.spawn(
                "prober", [sys.executable, "-c", SENDER, network.router, str(port), str(PROBES)], log_file=log
            )
        delays = []
        try:
            while True:
                payload, ancillary, _, _ = receiver.recvmsg(64, socket.CMSG_SPACE(16))
                arrived = next(struct.unpack("qq", data[:16]) for _, kind, data in ancillary if kind == SO_TIMESTAMPNS)
                delays.append(arrived[0] + arrived[1] * 1e-9 - np.frombuffer(payload[4:12], dtype=">f8")[0])
        except TimeoutError:
            pass
        assert sender.wait(timeout=30) == 0
    delivered = len(delays) / PROBES
    sigma = np.sqrt(0.05 * 0.95 / PROBES)
    assert abs(delivered - 0.95) < 3 * sigma, delivered
    p50, p99 = np.percentile(delays, [50, 99])
    assert 0.099 < p50 < 0.106, p50  # the set 100 ms, plus the hub's scheduling
    assert p99 < 0.125, p99
    report = json.loads((tmp_path / "network.json").read_text())
    # The hub's count of what it passed, against what arrived: a datagram it
    # passed may still overflow the receiving socket's buffer on a busy host.
    assert 0 <= report["prober -> hub"]["counts"]["delivered"] - len(delays) <= 2
    assert leftovers(added) == NOTHING


def run_kernel_game(tmp_path, *extra):
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "bearcat",
            "run",
            "fake-out",
            "--network",
            "kernel",
            "--out",
            str(tmp_path / "run"),
            *extra,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )


@needs_kernel
def test_a_live_game_under_3g_in_kernel_mode_ends_with_a_verdict(tmp_path):
    launcher = run_kernel_game(tmp_path, "--netem", "3g")
    output, _ = launcher.communicate(timeout=600)
    assert launcher.returncode == 0, output
    assert "impaired by profile 3g in an NFQUEUE hub (this kernel has" in output  # says which machinery
    outcome = json.loads((tmp_path / "run" / "outcome.json").read_text())
    assert outcome["ended"] and outcome["winner"] in ("attacker", "defender"), outcome
    report = json.loads((tmp_path / "run" / "network.json").read_text())
    assert set(report) == {"attacker -> hub", "hub -> attacker", "defender -> hub", "hub -> defender"}
    for direction, seen in report.items():
        assert seen["counts"]["delivered"] > 50, direction
        assert 0.115 <= seen["delay_s"]["p50"] < 0.2, direction  # 3g: 115 ms and a heavy tail
    assert leftovers(added_by(tmp_path)) == NOTHING


@needs_kernel
def test_a_launcher_killed_with_sigkill_leaves_nothing_behind(tmp_path):
    launcher = run_kernel_game(tmp_path, "--netem", "wifi")
    wait_for_the_start(launcher)
    added = added_by(tmp_path)
    assert leftovers(added)["interfaces"], "the run's link to its hub is up while it plays"
    # While it plays, the checker counts what the run started: its peers, its hub, its link.
    playing = next(f for f in check_run(tmp_path / "run") if f.name == "leftovers")
    assert playing.held is False, playing.evidence
    assert all(f"{name} (pid " in playing.evidence for name in ("gs", "attacker", "defender", "hub")), playing.evidence
    assert playing.evidence.endswith(f"link {added['link']}, route {added['route']}"), playing.evidence
    os.kill(launcher.pid, signal.SIGKILL)
    launcher.wait(timeout=10)
    # Nobody is left to delete the link: it goes when the kernel tears the
    # hub's namespace down, in the background, once its last process died.
    end = time.monotonic() + 10
    while time.monotonic() < end and (leftovers(added) != NOTHING or peers_of(tmp_path)):
        time.sleep(0.1)
    assert peers_of(tmp_path) == []
    assert leftovers(added) == NOTHING
    assert next(f for f in check_run(tmp_path / "run") if f.name == "leftovers").held is True


@needs_kernel
@pytest.mark.parametrize("ending", ["ctrl-c", "a walker's death"])
def test_a_run_ended_by_ctrl_c_or_by_a_peers_death_leaves_nothing_behind(tmp_path, ending):
    launcher = run_kernel_game(tmp_path, "--netem", "wifi")
    wait_for_the_start(launcher)
    if ending == "ctrl-c":
        os.killpg(launcher.pid, signal.SIGINT)  # what a terminal sends to its foreground group
    else:
        command = {p: Path(f"/proc/{p}/cmdline").read_text().replace("\0", " ") for p in peers_of(tmp_path)}
        (walker,) = [
            p for p, line in command.items() if line.startswith(sys.executable) and "/peers/defender.spec.json" in line
        ]
        os.kill(walker, signal.SIGKILL)
    output, _ = launcher.communicate(timeout=120)
    outcome = json.loads((tmp_path / "run" / "outcome.json").read_text())
    assert outcome["ended"] or "interrupted" in outcome["reason"], output
    assert peers_of(tmp_path) == []
    assert leftovers(added_by(tmp_path)) == NOTHING, output
    if ending == "ctrl-c":  # the hub carried their goodbyes: nobody had to be killed
        assert all(code is not None and code >= 0 for code in outcome["peers"].values()), outcome["peers"]


def wait_for_the_start(launcher: subprocess.Popen) -> None:
    seen = ""
    for line in launcher.stdout:  # until the launcher says so, or ends
        seen += line
        if "game started" in line:
            return
    pytest.fail(f"the launcher ended (exit {launcher.wait()}) before the game started:\n{seen}")


def peers_of(tmp_path: Path) -> list[int]:
    """The processes still running a peer of this test's run."""
    found = subprocess.run(["pgrep", "-f", str(tmp_path / "run")], capture_output=True, text=True).stdout
    return [int(pid) for pid in found.split()]


@pytest.mark.skipif(
    shutil.which("setpriv") is None, reason="needs setpriv to drop the capabilities: apt-get install util-linux"
)
def test_without_the_capabilities_kernel_mode_is_one_sentence_before_anything_starts(tmp_path):
    run = subprocess.run(
        ["setpriv", "--bounding-set=-sys_admin,-net_admin", "--inh-caps=-sys_admin,-net_admin"]
        + [sys.executable, "-m", "bearcat", "run", "fake-out", "--network", "kernel", "--out", str(tmp_path / "run")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2
    assert run.stderr.startswith("bearcat: error: --network kernel needs root, or the capabilities CAP_SYS_ADMIN")
    assert len(run.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "run").exists()
