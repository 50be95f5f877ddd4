"""What a fault does inside a peer, the same in both runtimes.

A partition or an outage cuts the shim's links between sides; a degraded
link follows another profile; a clock jumps or drifts; a phone's GPS lies.
The simulated injector applies these to the agents it holds, and a live
peer applies them when the launcher announces the fault; processes,
kernel networks and disks are the launchers' own business.
"""

from __future__ import annotations

from collections.abc import Callable

from bearcat.netem.profiles import load_profile
from bearcat.scenarios.faults import GROUND, LAUNCHER, Clock, Degrade, Fault, Gps, Heal, Outage, Partition

NETWORK_KINDS = ("partition", "outage", "heal", "degrade")


def noted(record, k: int, fault: Fault, now: float) -> dict:
    """Note fault ``k`` in the event log as it starts; its entry in the run's outcome."""
    peers = list(fault.peers())
    record.note(now, "fault", fault=k, kind=fault.kind, peers=peers, describe=fault.describe())
    return {"fault": k, "kind": fault.kind, "peers": peers, "t": now}


def sides(fault: Partition | Outage) -> tuple[dict[str, int], int]:
    """The side of each peer a cut names, and the side of those it does not
    (the ground station's, with the launcher beside it)."""
    if isinstance(fault, Outage):
        side, rest = {fault.target: 1}, 0
    else:
        side = {peer: j for j, group in enumerate(fault.groups) for peer in group}
        rest = side.get(GROUND, len(fault.groups))
    return {**side, LAUNCHER: side.get(GROUND, rest)}, rest


def apply_network(fault: Fault, shim, start: float, end: float | None, members: Callable[[str], list[str]]) -> None:
    """Cut, heal or degrade ``shim``'s links from ``start`` (on the shim's
    clock) until ``end``; ``members(peer)`` are the session names of a peer."""
    if isinstance(fault, Partition | Outage):
        side, rest = sides(fault)
        shim.cut({name: j for peer, j in side.items() for name in members(peer)}, start, end, rest)
    elif isinstance(fault, Heal):
        shim.heal(start)
    elif isinstance(fault, Degrade):
        shim.degrade(set(members(fault.target)), load_profile(fault.profile).link, fault.profile, start, end)


def skewed(fault: Clock, start: float) -> Callable[[float], float]:
    """The peer's own time as a function of the runtime's, from ``start`` on."""
    return lambda t: t + fault.offset + fault.drift * (t - start)


def lie(fault: Gps) -> tuple[str, tuple[float, float]]:
    """What the phone's GPS reports instead of the truth (``Phone.lie``)."""
    if fault.mode != "spoof":
        return fault.mode, fault.offset
    assert fault.position is not None  # a spoof's position is required when the plan is read
    return fault.mode, fault.position
