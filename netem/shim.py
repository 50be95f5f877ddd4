"""The shim that applies a link model to every directed link, the same way
in both runtimes.

It sits at the receiving end: the bus hands it each message with its
sender, receiver, key and time of sending, and it answers when (and how
many times) the message arrives, or that it never does. Each directed link
has its own generator, spawned from the run's seed and the two peer names,
so one link's draws do not depend on which other links exist or how busy
they are.

How a message fares depends on how Zenoh carries it (``netem.link``).
Reliable ones (game state, control, UAV tasks) always ride a TCP stream:
never lost, a loss costs a retransmission and holds what follows, an outage
holds them until it ends. Best-effort ones (fixes, guidance) ride the same
stream when the run's ``transport`` is "tcp" (late, in bursts, never lost)
and datagrams when it is "udp" (lost outright, in order otherwise); the
shim was calibrated against the kernel's real TCP and Zenoh over UDP
(benchmarks/network_calibration.py). Messages to or from a peer standing in
a dead zone (no signal between buildings) are lost, or held and released by
``poll`` once both ends have signal again.

Every decision is reported to ``record`` as an ``Impairment``: delivered
with what delay and why, duplicated, dropped and why, so an analysis can
tell a late fix from a lost one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import shapely

from bearcat.bus import keys
from bearcat.bus.errors import BusError
from bearcat.netem.link import LinkState, link_rng
from bearcat.netem.models import LinkModel

# Keys the shim never impairs: the simulation's ground truth, the launcher's
# control channel (a local wire in the field) and liveliness.
EXEMPT_KINDS = ("truth", "control", "alive", "map", "scenario")


@dataclass(frozen=True)
class Delivery:
    """The message arrives at ``at`` (seconds); ``copy`` 1 for a duplicate."""

    at: float
    payload: bytes
    copy: int = 0


@dataclass(frozen=True)
class Impairment:
    """One record of the event log: what the shim did to one message (or copy)."""

    sent: float
    sender: str
    receiver: str
    key: str
    size: int
    action: str  # "delivered", "duplicated", "dropped" or "held"
    delay: float | None = None
    reasons: tuple[str, ...] = ()


class Shim:
    """Applies ``model`` to every directed link between distinct peers.

    ``dead_zones`` is a shapely geometry in the map's local metres and
    ``where(peer)`` the peer's true position there (None for a peer that has
    none, like the ground station); ``record`` receives every Impairment;
    links between two ``colocated`` peers (the ground station's services on
    one laptop) are never impaired. ``epoch`` is when the game started on
    the clock ``now`` is read from (0 in simulation's game time); the
    model's outage windows count from it, and none applies while it is None
    (a live peer learns it from the start command). ``transport`` is how
    best-effort messages travel: "tcp" or "udp"."""

    def __init__(
        self,
        model: LinkModel,
        seed: int,
        *,
        dead_zones=None,
        where: Callable[[str], tuple[float, float] | None] | None = None,
        record: Callable[[Impairment], None] | None = None,
        colocated: tuple[str, ...] = (),
        epoch: float | None = 0.0,
        transport: str = "tcp",
    ) -> None:
        if dead_zones is not None and where is None:
            raise BusError("dead zones need a 'where' that gives each peer's position")
        self.model = model
        self.seed = int(seed)
        self.dead_zones = dead_zones
        if dead_zones is not None:
            shapely.prepare(dead_zones)
        self.where = where
        self.record = record or (lambda impairment: None)
        self.colocated = tuple(colocated)
        self.epoch = epoch
        self.transport = transport
        self._links: dict[tuple[str, str], LinkState] = {}
        self._held: list[tuple] = []

    def link(self, sender: str, receiver: str) -> LinkState:
        state = self._links.get((sender, receiver))
        if state is None:
            state = self._links[(sender, receiver)] = LinkState(self.model, link_rng(self.seed, sender, receiver))
        return state

    def transmit(self, sender: str, receiver: str, key: str, payload: bytes, now: float, token=None) -> list[Delivery]:
        """The arrivals of a message ``sender`` put on ``key`` at ``now`` for
        ``receiver``: none if it is lost or held, two if duplicated. A held
        message comes back from ``poll`` with ``token``."""
        reliable, exempt = _kind(key)
        reliable = reliable or self.transport == "tcp"  # over tcp/ every message rides the TCP stream
        local = sender == receiver or (sender in self.colocated and receiver in self.colocated)
        if exempt or local or (self.model.ideal and self.dead_zones is None):
            return [Delivery(now, payload)]
        if self._dead(sender, receiver):
            if reliable:
                self._held.append((now, sender, receiver, key, payload, token))
                self._log(now, sender, receiver, key, payload, "held", None, ("dead zone",))
            else:
                self._log(now, sender, receiver, key, payload, "dropped", None, ("dead zone",))
            return []
        return self._send(sender, receiver, key, payload, now, now, reliable)

    def poll(self, now: float) -> list[tuple[object, Delivery]]:
        """Held reliable messages whose link has signal again at ``now``, as
        ``(token, delivery)``, in the order they were sent."""
        released, still = [], []
        for held in self._held:
            sent, sender, receiver, key, payload, token = held
            if self._dead(sender, receiver):
                still.append(held)
                continue
            for d in self._send(sender, receiver, key, payload, sent, now, True):
                released.append((token, d))
        self._held = still
        return released

    # ------------------------------------------------------------------ internals

    def _send(self, sender, receiver, key, payload, sent, now, reliable) -> list[Delivery]:
        game_time = None if self.epoch is None else now - self.epoch
        way = "stream" if reliable else "datagram"
        fate = self.link(sender, receiver).carry(now, len(payload), way=way, game_time=game_time)
        if fate.lost is not None:
            self._log(sent, sender, receiver, key, payload, "dropped", None, (fate.lost,))
            return []
        arrivals = []
        for copy, c in enumerate(fate.copies):
            arrivals.append(Delivery(c.at, payload, copy))
            action = "duplicated" if copy else "delivered"
            self._log(sent, sender, receiver, key, payload, action, c.at - sent, c.reasons)
        return arrivals

    def _dead(self, sender: str, receiver: str) -> bool:
        if self.dead_zones is None:
            return False
        for peer in (sender, receiver):
            p = self.where(peer)
            if p is not None and shapely.contains_xy(self.dead_zones, *p):
                return True
        return False

    def _log(self, sent, sender, receiver, key, payload, action, delay, reasons) -> None:
        self.record(Impairment(sent, sender, receiver, key, len(payload), action, delay, reasons))


def _kind(key: str) -> tuple[bool, bool]:
    """(reliable, exempt) for a key."""
    try:
        kind = keys.parse(key).kind
    except BusError:
        return True, True  # not a game key: pass it through untouched
    return kind not in keys.BEST_EFFORT_KINDS, kind in EXEMPT_KINDS
