"""When each packet of a link leaves the hub, drawn from the link's model.

A packet is carried like a best-effort message (``netem.link``): lost to
loss, bursts and outages, late by the radio's promotion, the serialiser and
the delay, sometimes duplicated, sometimes sent ahead of the delay's base.
On top of that a link keeps its packets in order, as a cellular bearer does
(RLC delivers in sequence): a packet drawn a shorter delay than the one
before it waits for it, and only a reordered packet overtakes. Whatever the
transport above needs (TCP's retransmissions) it does itself.
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
    last_release: float = float("-inf")
    counts: dict[str, int] = field(default_factory=dict)
    delays: deque = field(default_factory=lambda: deque(maxlen=100_000))  # s, the latest packets'

    def schedule(self, now: float, size: int, game_time: float | None) -> list[float]:
        """The times (on ``now``'s clock) the packet's copies leave: none if it is lost, two if duplicated."""
        fate = self.state.carry(now, size, reliable=False, game_time=game_time)
        if fate.lost is not None:
            self._count(fate.lost)
            return []
        releases = []
        for copy in fate.copies:
            at = copy.at
            if "reordered" not in copy.reasons:
                at = max(at, self.last_release)
                self.last_release = at
            releases.append(at)
        self._count("delivered")
        if len(releases) > 1:
            self._count("duplicated")
        self.delays.append(releases[0] - now)
        return releases

    def _count(self, what: str) -> None:
        self.counts[what] = self.counts.get(what, 0) + 1
