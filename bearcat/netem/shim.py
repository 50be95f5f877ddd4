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

Faults act here too (``cut``, ``heal``, ``degrade``): a partition or an
outage cuts links for a while, and a degraded link follows another
profile's model. A cut link loses what travels best effort; what travels
reliably waits in its TCP stream and arrives when the cut ends, unless the
cut outlasted the session's ``lease``: then the session died with what it
carried.

Every decision is reported to ``record`` as an ``Impairment``: delivered
with what delay and why, duplicated, dropped and why, so an analysis can
tell a late fix from a lost one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import shapely

from bearcat.bus import keys
from bearcat.bus.errors import BusError
from bearcat.netem.link import LinkState, link_rng
from bearcat.netem.models import LinkModel

# Keys the shim never impairs: the simulation's ground truth, the launcher's
# control and fault channels (a local wire in the field) and liveliness.
EXEMPT_KINDS = ("truth", "control", "fault", "alive", "map", "scenario")


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


@dataclass
class Cut:
    """Links between peers on different sides are down from ``start`` until
    ``end`` (None: until healed); ``side`` gives each peer's group, and
    peers it does not name are on side ``rest``."""

    side: dict[str, int]
    start: float
    end: float | None = None
    rest: int = 0

    def severs(self, sender: str, receiver: str, now: float) -> bool:
        if now < self.start or (self.end is not None and now >= self.end):
            return False
        return self.side.get(sender, self.rest) != self.side.get(receiver, self.rest)


@dataclass(frozen=True)
class Degradation:
    """The links of ``peers`` follow ``model`` from ``start`` until ``end``."""

    peers: frozenset[str]
    model: LinkModel
    name: str
    start: float
    end: float
    states: dict = field(default_factory=dict, compare=False)

    def covers(self, sender: str, receiver: str, now: float) -> bool:
        return self.start <= now < self.end and (sender in self.peers or receiver in self.peers)


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
    best-effort messages travel: "tcp" or "udp"; ``lease``, how long a
    session outlives a cut link."""

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
        lease: float = math.inf,
    ) -> None:
        if dead_zones is not None and where is None:
            raise BusError("dead zones need a 'where' that gives each peer's position")
        self.model = model
        self._ideal = model.ideal  # asked on every message; a model is frozen
        self.seed = int(seed)
        self.dead_zones = dead_zones
        if dead_zones is not None:
            shapely.prepare(dead_zones)
        self.where = where
        self.record = record or (lambda impairment: None)
        self.colocated = tuple(colocated)
        self.epoch = epoch
        self.transport = transport
        self.lease = lease
        self.cuts: list[Cut] = []
        self.degradations: list[Degradation] = []
        self._links: dict[tuple[str, str], LinkState] = {}
        self._held: list[tuple] = []

    def link(self, sender: str, receiver: str, now: float = -math.inf) -> LinkState:
        """The state of the link at ``now``: its own, or that of a degradation in force."""
        for d in self.degradations:
            if d.covers(sender, receiver, now):
                states = d.states
                break
        else:
            states = self._links
        state = states.get((sender, receiver))
        if state is None:
            model = self.model if states is self._links else d.model
            state = states[(sender, receiver)] = LinkState(model, link_rng(self.seed, sender, receiver))
        return state

    @property
    def faulted(self) -> bool:
        """Whether anything is held or may be cut: ``poll`` has work."""
        return bool(self.cuts or self.dead_zones is not None)

    def cut(self, side: dict[str, int], start: float, end: float | None = None, rest: int = 0) -> Cut:
        """Cut the links between peers on different sides from ``start`` (see ``Cut``)."""
        self.cuts.append(c := Cut(dict(side), start, end, rest))
        return c

    def heal(self, now: float) -> None:
        """End every cut in force at ``now``."""
        for c in self.cuts:
            if c.end is None or c.end > now:
                c.end = max(now, c.start)

    def degrade(self, peers, model: LinkModel, name: str, start: float, end: float) -> None:
        """The links of ``peers`` follow ``model`` (profile ``name``) from ``start`` until ``end``."""
        self.degradations.append(Degradation(frozenset(peers), model, name, start, end))

    def transmit(self, sender: str, receiver: str, key: str, payload: bytes, now: float, token=None) -> list[Delivery]:
        """The arrivals of a message ``sender`` put on ``key`` at ``now`` for
        ``receiver``: none if it is lost or held, two if duplicated. A held
        message comes back from ``poll`` with ``token``."""
        reliable, exempt = _kind(key)
        reliable = reliable or self.transport == "tcp"  # over tcp/ every message rides the TCP stream
        local = sender == receiver or (sender in self.colocated and receiver in self.colocated)
        if exempt or local or (self._ideal and not self.faulted and not self.degradations):
            return [Delivery(now, payload)]
        blocked = self._blocked(sender, receiver, now)
        if blocked is not None:
            if reliable:
                self._held.append((now, sender, receiver, key, payload, token))
                self._log(now, sender, receiver, key, payload, "held", None, (blocked,))
            else:
                self._log(now, sender, receiver, key, payload, "dropped", None, (blocked,))
            return []
        return self._send(sender, receiver, key, payload, now, now, reliable)

    def poll(self, now: float) -> list[tuple[object, Delivery]]:
        """Held reliable messages whose link has signal again at ``now``, as
        ``(token, delivery)``, in the order they were sent; those held across
        a cut that outlasted the lease are dropped with their session."""
        released, still = [], []
        for held in self._held:
            sent, sender, receiver, key, payload, token = held
            if self._blocked(sender, receiver, now) is not None:
                still.append(held)
                continue
            if any(
                c.severs(sender, receiver, sent) and c.end is not None and c.end - c.start >= self.lease
                for c in self.cuts
            ):
                self._log(sent, sender, receiver, key, payload, "dropped", None, ("session lost",))
                continue
            for d in self._send(sender, receiver, key, payload, sent, now, True):
                released.append((token, d))
        self._held = still
        return released

    # ------------------------------------------------------------------ internals

    def _send(self, sender, receiver, key, payload, sent, now, reliable) -> list[Delivery]:
        game_time = None if self.epoch is None else now - self.epoch
        way = "stream" if reliable else "datagram"
        fate = self.link(sender, receiver, now).carry(now, len(payload), way=way, game_time=game_time)
        if fate.lost is not None:
            self._log(sent, sender, receiver, key, payload, "dropped", None, (fate.lost,))
            return []
        arrivals = []
        for copy, c in enumerate(fate.copies):
            arrivals.append(Delivery(c.at, payload, copy))
            action = "duplicated" if copy else "delivered"
            self._log(sent, sender, receiver, key, payload, action, c.at - sent, c.reasons)
        return arrivals

    def _blocked(self, sender: str, receiver: str, now: float) -> str | None:
        """Why nothing crosses from ``sender`` to ``receiver`` at ``now``, or None."""
        if any(c.severs(sender, receiver, now) for c in self.cuts):
            return "partition"
        if self.dead_zones is None or self.where is None:
            return None
        for peer in (sender, receiver):
            p = self.where(peer)
            if p is not None and shapely.contains_xy(self.dead_zones, *p):
                return "dead zone"
        return None

    def _log(self, sent, sender, receiver, key, payload, action, delay, reasons) -> None:
        self.record(Impairment(sent, sender, receiver, key, len(payload), action, delay, reasons))


def _kind(key: str) -> tuple[bool, bool]:
    """(reliable, exempt) for a key."""
    try:
        kind = keys.parse(key).kind
    except BusError:
        return True, True  # not a game key: pass it through untouched
    return kind not in keys.BEST_EFFORT_KINDS, kind in EXEMPT_KINDS
