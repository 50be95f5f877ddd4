"""The shim that applies a link model to every directed link, the same way
in both runtimes.

It sits at the receiving end: the bus hands it each message with its
sender, receiver, key and time of sending, and it answers when (and how
many times) the message arrives, or that it never does. Each directed link
has its own generator, spawned from the run's seed and the two peer names,
so one link's draws do not depend on which other links exist or how busy
they are.

Best-effort messages (fixes, guidance) are lost outright. Reliable ones
(game state, control, UAV tasks) are never lost, as over Zenoh's TCP links:
a loss costs a retransmission timeout and another try, an outage holds them
until it ends, and they keep their order on the link. Messages to or from a
peer standing in a dead zone (no signal between buildings) are lost, or held
and released by ``poll`` once both ends have signal again.

Every decision is reported to ``record`` as an ``Impairment``: delivered
with what delay and why, duplicated, dropped and why, so an analysis can
tell a late fix from a lost one.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import shapely

from bearcat.bus import keys
from bearcat.bus.errors import BusError
from bearcat.netem.models import LinkModel

# Keys the shim never impairs: the simulation's ground truth, the launcher's
# control channel (a local wire in the field) and liveliness.
EXEMPT_KINDS = ("truth", "control", "alive", "map", "scenario")
_MAX_TRIES = 50


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


class _Link:
    __slots__ = ("bad", "busy_until", "last_reliable", "last_sent", "rng")

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.bad = False
        self.last_sent = -np.inf
        self.busy_until = -np.inf
        self.last_reliable = -np.inf


class Shim:
    """Applies ``model`` to every directed link between distinct peers.

    ``dead_zones`` is a shapely geometry in the map's local metres and
    ``where(peer)`` the peer's true position there (None for a peer that has
    none, like the ground station); ``record`` receives every Impairment;
    links between two ``colocated`` peers (the ground station's services on
    one laptop) are never impaired."""

    def __init__(
        self,
        model: LinkModel,
        seed: int,
        *,
        dead_zones=None,
        where: Callable[[str], tuple[float, float] | None] | None = None,
        record: Callable[[Impairment], None] | None = None,
        colocated: tuple[str, ...] = (),
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
        self._links: dict[tuple[str, str], _Link] = {}
        self._held: list[tuple] = []

    def link(self, sender: str, receiver: str) -> _Link:
        state = self._links.get((sender, receiver))
        if state is None:
            spawn = (zlib.crc32(sender.encode()), zlib.crc32(receiver.encode()))
            state = _Link(np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=spawn)))
            self._links[(sender, receiver)] = state
        return state

    def transmit(self, sender: str, receiver: str, key: str, payload: bytes, now: float, token=None) -> list[Delivery]:
        """The arrivals of a message ``sender`` put on ``key`` at ``now`` for
        ``receiver``: none if it is lost or held, two if duplicated. A held
        message comes back from ``poll`` with ``token``."""
        reliable, exempt = _kind(key)
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
        m, link = self.model, self.link(sender, receiver)
        rng, reasons = link.rng, []
        start = now
        for outage in m.outages:
            if outage.covers(start):
                if not reliable:
                    self._log(sent, sender, receiver, key, payload, "dropped", None, ("outage",))
                    return []
                start, reasons = outage.end, [*reasons, "outage"]
        if m.idle_after > 0 and start - link.last_sent > m.idle_after and np.isfinite(link.last_sent):
            start += rng.uniform(*m.promotion)
            reasons.append("promotion")
        link.last_sent = start
        if m.rate > 0:
            start = max(start, link.busy_until) + len(payload) / m.rate
            link.busy_until = start
        tries = 0
        while self._lost(link):
            if not reliable:
                why = "burst" if link.bad else "loss"
                self._log(sent, sender, receiver, key, payload, "dropped", None, (why,))
                return []
            tries += 1
            if tries >= _MAX_TRIES:
                break
            start += m.retransmit
        if tries:
            reasons.append(f"retransmitted x{tries}")
        arrivals = []
        for copy in (0, 1):
            if copy == 1 and not rng.random() < m.duplicate:
                break
            skip = not reliable and m.reorder > 0 and rng.random() < m.reorder
            at = start + (m.delay.sample(rng) - (m.delay.base if skip else 0.0))
            why = [*reasons, "reordered"] if skip else list(reasons)
            if reliable:
                at = max(at, link.last_reliable)
                link.last_reliable = at
            arrivals.append(Delivery(at, payload, copy))
            action = "duplicated" if copy else "delivered"
            self._log(sent, sender, receiver, key, payload, action, at - sent, tuple(why))
        return arrivals

    def _lost(self, link: _Link) -> bool:
        m, rng = self.model, link.rng
        lost = m.loss > 0 and rng.random() < m.loss
        if m.burst is not None:
            b = m.burst
            link.bad = (rng.random() >= b.r) if link.bad else (rng.random() < b.p)
            lost = lost or rng.random() < (b.loss_bad if link.bad else b.loss_good)
        return lost

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
