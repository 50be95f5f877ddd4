"""One directed link in motion: what a link model must remember between
messages (the radio's idle timer, the serialiser, the Gilbert-Elliott state,
the order reliable messages keep) and the draws that decide one message's
fate.

The bus shim carries messages with it and the kernel hub packets, so a
profile impairs a link the same way in both: the same outages, promotion
delays, rate, loss and bursts, duplicates, reordering and delay, drawn in
the same order from the link's own generator.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from bearcat.netem.models import LinkModel

MAX_TRIES = 50
"""A reliable message that is lost this many times in a row goes anyway: a
link that loses everything would otherwise never deliver it."""


@dataclass(frozen=True)
class Copy:
    """One copy of a message reaches the far end at ``at`` (seconds)."""

    at: float
    reasons: tuple[str, ...]  # why it was late: promotion, outage, retransmitted xN, reordered


@dataclass(frozen=True)
class Fate:
    """What the link did to one message: its copies (none if it was lost) and, if lost, why."""

    copies: tuple[Copy, ...]
    lost: str | None = None  # "loss", "burst" or "outage"


def link_rng(seed: int, sender: str, receiver: str) -> np.random.Generator:
    """The generator of the directed link ``sender`` -> ``receiver`` in a run
    seeded ``seed``: its own stream, whatever other links exist."""
    spawn = (zlib.crc32(sender.encode()), zlib.crc32(receiver.encode()))
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=spawn))


class LinkState:
    """The state and the draws of one directed link under ``model``."""

    __slots__ = ("bad", "busy_until", "last_reliable", "last_sent", "model", "rng")

    def __init__(self, model: LinkModel, rng: np.random.Generator) -> None:
        self.model = model
        self.rng = rng
        self.bad = False  # the Gilbert-Elliott state
        self.last_sent = -np.inf
        self.busy_until = -np.inf
        self.last_reliable = -np.inf

    def carry(self, now: float, size: int, *, reliable: bool, game_time: float | None = None) -> Fate:
        """The fate of a message of ``size`` bytes that enters the link at
        ``now``. ``game_time`` is ``now`` on the clock the model's outage
        windows are written in (None: before the game, when none applies).
        A best-effort message is lost to a loss or an outage; a reliable one
        waits them out and keeps its order behind the reliable ones before it."""
        m, rng = self.model, self.rng
        start, reasons = now, []
        if game_time is not None:
            for outage in m.outages:
                if outage.covers(game_time + (start - now)):
                    if not reliable:
                        return Fate((), "outage")
                    start, reasons = now + (outage.end - game_time), [*reasons, "outage"]
        if m.idle_after > 0 and start - self.last_sent > m.idle_after and np.isfinite(self.last_sent):
            start += rng.uniform(*m.promotion)
            reasons.append("promotion")
        self.last_sent = start
        if m.rate > 0:
            start = max(start, self.busy_until) + size / m.rate
            self.busy_until = start
        tries = 0
        while self._lost():
            if not reliable:
                return Fate((), "burst" if self.bad else "loss")
            tries += 1
            if tries >= MAX_TRIES:
                break
            start += m.retransmit
        if tries:
            reasons.append(f"retransmitted x{tries}")
        copies = []
        for copy in (0, 1):
            if copy == 1 and not rng.random() < m.duplicate:
                break
            skip = not reliable and m.reorder > 0 and rng.random() < m.reorder
            at = start + (m.delay.sample(rng) - (m.delay.base if skip else 0.0))
            if reliable:
                at = max(at, self.last_reliable)
                self.last_reliable = at
            copies.append(Copy(at, (*reasons, "reordered") if skip else tuple(reasons)))
        return Fate(tuple(copies))

    def _lost(self) -> bool:
        m, rng = self.model, self.rng
        lost = m.loss > 0 and rng.random() < m.loss
        if m.burst is not None:
            b = m.burst
            self.bad = (rng.random() >= b.r) if self.bad else (rng.random() < b.p)
            lost = lost or rng.random() < (b.loss_bad if self.bad else b.loss_good)
        return lost
