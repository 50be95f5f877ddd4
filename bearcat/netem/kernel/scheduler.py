"""When each packet of a link leaves the hub, drawn from the link's model.

A packet is carried as ``netem.link`` carries one (``way="packet"``): lost
to loss, bursts and outages, late by the radio's promotion, the serialiser
and the delay, kept in order behind the packets before it as a cellular
bearer keeps them, sometimes duplicated, and sometimes sent ahead of the
delay's base, overtaking those in flight. Whatever the transport above
needs (TCP's retransmissions) it does itself.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from bearcat.netem.link import LinkState


@dataclass
class Direction:
    """One direction of one peer's link: its draws and the order it keeps."""

    name: str  # e.g. "attacker -> hub"
    state: LinkState
    counts: dict[str, int] = field(default_factory=dict)
    delays: deque = field(default_factory=lambda: deque(maxlen=100_000))  # s, the latest packets'
    cut: bool = False  # a partition or an outage: every packet is dropped
    own: LinkState | None = None  # the link's own state while a degradation stands in for it

    def schedule(self, now: float, size: int, game_time: float | None) -> list[float]:
        """The times (on ``now``'s clock) the packet's copies leave: none if it is lost, two if duplicated."""
        if self.cut:
            self._count("partition")
            return []
        fate = self.state.carry(now, size, way="packet", game_time=game_time)
        if fate.lost is not None:
            self._count(fate.lost)
            return []
        releases = [copy.at for copy in fate.copies]
        self._count("delivered")
        if len(releases) > 1:
            self._count("duplicated")
        self.delays.append(releases[0] - now)
        return releases

    def _count(self, what: str) -> None:
        self.counts[what] = self.counts.get(what, 0) + 1
