"""One directed link in motion: what a link model must remember between
messages and the draws that decide one message's fate.

The bus shim carries messages with it and the kernel hub packets, so a
profile impairs a link the same way in both: the same outages, promotion
delays, rate, loss and bursts, duplicates, reordering and delay, drawn in
the same order from the link's own generator.

A message travels one of two ways, as it does over Zenoh:

- as datagrams (Zenoh over ``udp/``, and every packet in the kernel hub):
  lost if any of its packets is lost; the link keeps them in order, as a
  cellular bearer does, and only a reordered one skips ahead of those in
  flight. Zenoh drops a best-effort message older than one it already
  delivered, so a reordered message costs one: the model drops it.
- in a TCP stream (Zenoh over ``tcp/``): never lost; each lost packet is
  sent again once the sender notices (``Tcp``), and nothing behind it in
  the stream is delivered before it (head-of-line blocking), so a loss
  becomes a stall followed by a burst.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np

from bearcat.netem.models import LinkModel

MAX_LOSSES = 30
"""Tries after which a packet the link keeps losing is let through: no game outlasts the backed-off timers."""

MSS = 1448
"""Bytes of payload per packet: an Ethernet MTU less the IP and TCP headers."""


@dataclass(frozen=True)
class Copy:
    """One copy of a message reaches the far end at ``at`` (seconds)."""

    at: float
    reasons: tuple[str, ...]  # why it was late: promotion, outage, retransmitted xN, reordered


@dataclass(frozen=True)
class Fate:
    """What the link did to one message: its copies (none if it was lost) and, if lost, why."""

    copies: tuple[Copy, ...]
    lost: str | None = None  # "loss", "burst", "outage" or "reordered"


@dataclass(frozen=True)
class Tcp:
    """How a TCP sender recovers a lost packet, on a link of this model (Linux's defaults).

    The first time a packet is lost the sender learns it from the
    acknowledgements of what follows (RACK: once a later packet is
    acknowledged, after a quarter of a round trip more), or from its tail
    loss probe two round trips after it went quiet, whichever comes first.
    If the packet is lost again the retransmission timer takes over, at
    least ``MIN_RTO``, doubling with every further loss. The round trip is
    both directions' mean delay; its variation, both jitters."""

    srtt: float
    rto: float

    MIN_RTO = 0.2  # s: Linux's floor on the retransmission timeout
    MAX_RTO = 120.0

    @classmethod
    def of(cls, model: LinkModel) -> Tcp:
        srtt = 2.0 * model.delay.mean
        rttvar = math.sqrt(2.0) * model.delay.jitter
        return cls(srtt=srtt, rto=min(max(cls.MIN_RTO, srtt + 4.0 * rttvar), cls.MAX_RTO))

    def recovery(self, losses: int, gap: float) -> float:
        """Seconds a packet lost ``losses`` times in a row waits before its
        last try; ``gap``, seconds until the stream's next packet."""
        if losses == 0:
            return 0.0
        first = min(gap + 1.25 * self.srtt, 3.0 * self.srtt) if self.srtt > 0 else self.MIN_RTO
        return first + sum(min(self.rto * 2.0**k, self.MAX_RTO) for k in range(losses - 1))


def link_rng(seed: int, sender: str, receiver: str) -> np.random.Generator:
    """The generator of the directed link ``sender`` -> ``receiver`` in a run
    seeded ``seed``: its own stream, whatever other links exist."""
    spawn = (zlib.crc32(sender.encode()), zlib.crc32(receiver.encode()))
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=spawn))


class LinkState:
    """The state and the draws of one directed link under ``model``."""

    __slots__ = (
        "bad",
        "busy_until",
        "gap",
        "last_datagram",
        "last_entry",
        "last_sent",
        "last_stream",
        "model",
        "rng",
        "score",
        "scored_at",
        "sent_since",
        "slow_start",
        "tcp",
    )

    def __init__(self, model: LinkModel, rng: np.random.Generator) -> None:
        self.model = model
        self.rng = rng
        self.tcp = Tcp.of(model)
        self.bad = False  # the Gilbert-Elliott state
        self.last_sent = -np.inf
        self.busy_until = -np.inf
        self.last_datagram = -np.inf  # the latest datagram delivered in order
        self.last_stream = -np.inf  # the latest delivery of the TCP stream
        self.last_entry = -np.inf  # when the TCP stream last took a message
        self.gap = 0.25  # s between messages on the TCP stream (smoothed); Zenoh keeps a link alive at least so
        self.slow_start = -np.inf  # when the congestion window last restarted after a timeout
        self.score = 0.0  # the jitter's normal score, moving with time
        self.scored_at = -np.inf
        self.sent_since = 0  # packets the stream took since

    def carry(self, now: float, size: int, *, way: str, game_time: float | None = None) -> Fate:
        """The fate of a message of ``size`` bytes that enters the link at
        ``now``. ``way`` is how it travels: "datagram" (a Zenoh message over
        udp/), "stream" (over tcp/) or "packet" (one IP packet, as the kernel
        hub sees it: a reordered packet overtakes those in flight, and the
        transport above sorts it out). ``game_time`` is ``now`` on the clock
        the model's outage windows are written in (None: before the game,
        when none applies)."""
        m, rng = self.model, self.rng
        start = now
        reasons: list[str] = []
        if game_time is not None:
            for outage in m.outages:
                if outage.covers(game_time + (start - now)):
                    if way != "stream":
                        return Fate((), "outage")
                    start, reasons = now + (outage.end - game_time), [*reasons, "outage"]
        if m.idle_after > 0 and start - self.last_sent > m.idle_after and math.isfinite(self.last_sent):
            start += rng.uniform(*m.promotion)
            reasons.append("promotion")
        self.last_sent = start
        if m.rate > 0:
            start = max(start, self.busy_until) + size / m.rate
            self.busy_until = start
        packets = 1 if way == "packet" else max(1, -(-size // MSS))  # an IP packet of 1500 bytes is still one
        if way == "stream":
            return self._stream(start, packets, reasons)
        return self._datagram(start, packets, reasons, overtakes=way == "packet")

    def _datagram(self, start: float, packets: int, reasons: list[str], *, overtakes: bool) -> Fate:
        m, rng = self.model, self.rng
        lost = [why for why in (self._lost() for _ in range(packets)) if why is not None]
        if lost:
            return Fate((), lost[0])
        copies = []
        for copy in (0, 1):
            if copy == 1 and not rng.random() < m.duplicate:
                break
            if m.reorder > 0 and rng.random() < m.reorder:
                if not overtakes:
                    if copy == 0:
                        return Fate((), "reordered")
                    break
                copies.append(Copy(start + self._delay(start) - m.delay.base, (*reasons, "reordered")))
                continue
            at = max(start + self._delay(start), self.last_datagram)
            self.last_datagram = at
            copies.append(Copy(at, tuple(reasons)))
        return Fate(tuple(copies))

    def _stream(self, start: float, packets: int, reasons: list[str]) -> Fate:
        if math.isfinite(self.last_entry):
            self.gap += 0.2 * (min(start - self.last_entry, 1.0) - self.gap)
        self.last_entry = start
        retransmitted = 0
        for _ in range(packets):
            losses, waited = 0, 0.0
            while self._lost() is not None and losses < MAX_LOSSES:
                losses += 1
                # The sender learns of the loss from a later packet, and in a
                # burst the packets right after it are lost as well.
                later = self.gap * (1.0 + self._burst_left())
                step = self.tcp.recovery(losses, later) - self.tcp.recovery(losses - 1, later)
                waited += step
                self._pass(round(step / self.gap))  # what the link carries meanwhile may end the burst
            start += waited
            retransmitted += losses
            if losses >= 2:  # a timeout: the congestion window starts again from one packet
                self.slow_start, self.sent_since = start, 0
        if retransmitted:
            reasons.append(f"retransmitted x{retransmitted}")
        start = self._window(start, packets)
        at = max(start + self._delay(start), self.last_stream)
        self.last_stream = at
        return Fate((Copy(at, tuple(reasons)),))

    def _window(self, start: float, packets: int) -> float:
        """When the congestion window lets ``packets`` more go, after a timeout:
        slow start sends one packet in the first round trip, two in the
        next, four..., so what the stream took meanwhile waits its round."""
        if not math.isfinite(self.slow_start) or start < self.slow_start or self.tcp.srtt <= 0:
            return start
        self.sent_since += packets
        rounds = math.ceil(math.log2(self.sent_since + 1)) - 1  # the round whose window lets the last one go
        if 2.0**rounds * self.gap >= self.tcp.srtt:  # the window carries the stream again
            self.slow_start = -np.inf
        return max(start, self.slow_start + rounds * self.tcp.srtt)

    def _delay(self, t: float) -> float:
        """The delay of a packet sent at ``t``. With a ``jitter_time`` the
        jitter's normal score is an Ornstein-Uhlenbeck process in time, so the
        delay drifts rather than jumps and a busy link keeps its packets in
        order without its delays piling up behind one unlucky packet; each
        packet's delay still has the model's distribution."""
        m = self.model
        if m.jitter_time <= 0:
            return m.delay.sample(self.rng)
        if t > self.scored_at:
            a = math.exp(-(t - self.scored_at) / m.jitter_time) if math.isfinite(self.scored_at) else 0.0
            self.score = a * self.score + math.sqrt(1.0 - a * a) * float(self.rng.standard_normal())
            self.scored_at = t
        return m.delay.at(self.score)

    def _burst_left(self) -> float:
        """Packets the link is expected to lose after this one before it delivers again."""
        b = self.model.burst
        if b is None or not self.bad or b.r == 0:
            return 0.0
        return b.loss_bad * (1.0 / b.r - 1.0)

    def _pass(self, packets: int) -> None:
        """Let ``packets`` go by without drawing their fate: the Gilbert-Elliott
        state after them, drawn from the chain's ``packets``-step transition."""
        b = self.model.burst
        if b is None or packets <= 0:
            return
        settled = b.p / (b.p + b.r) if b.p + b.r > 0 else float(self.bad)
        bad = settled + (float(self.bad) - settled) * (1.0 - b.p - b.r) ** packets
        self.bad = self.rng.random() < bad

    def _lost(self) -> str | None:
        """Whether the next packet is lost, and to what."""
        m, rng = self.model, self.rng
        lost = m.loss > 0 and rng.random() < m.loss
        if m.burst is not None:
            b = m.burst
            self.bad = (rng.random() >= b.r) if self.bad else (rng.random() < b.p)
            if rng.random() < (b.loss_bad if self.bad else b.loss_good):
                return "burst" if self.bad else "loss"
        return "loss" if lost else None
