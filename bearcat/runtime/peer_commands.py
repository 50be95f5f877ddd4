"""What a live run's processes are started with besides a peer's spec
(``peer_spec``): the installation that runs them, a UAV's vehicle emulator,
free ports, and which peers a person starts instead.

Kept apart from the run itself so that the launcher's checks before a run,
the run, and the tests that start a peer by hand share them.
"""

from __future__ import annotations

import socket
import sys

from bearcat.agents.human.behaviour import TAKES_KEYS
from bearcat.scenarios.schema import Scenario

BEARCAT = (sys.executable, "-m", "bearcat")  # this very installation, whatever is on the PATH
VEHICLE = "udpin://0.0.0.0:14540"  # where a UAV peer started by hand listens for its vehicle (PX4 SITL's)


def free_port(kind=socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


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


def started_by_hand(scenario: Scenario, joins: tuple[str, ...]) -> set[str]:
    """The agents whose peers a person starts: those whose behaviour takes keys, and those named in ``joins``."""
    return set(joins) | {a.id for a in scenario.agents if scenario.behaviour_of(a.id).entry.has(TAKES_KEYS)}
