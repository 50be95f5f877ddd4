"""An attacker that feints only while the defender is near, then commits.

While its phone shows the defender within ``near`` metres, the attacker
runs legs of ``leg`` seconds to one side then the other of the line home,
``spread`` degrees off it: a defender who marks what it is shown follows
the feint, a stale report or two behind. Once the defender is shown
farther than ``near`` (it bit, or it was never close), the attacker goes
home for good along its phone's heading, or the shortest path when the
phone shows none.
"""

from __future__ import annotations

import math

import numpy as np

from bearcat.plugins import COMMITS, TELLS, Angle, Behaviour, Distance, Options, Period


class NearFeint(Behaviour):
    """Feint while the defender is shown near, then go home for good."""

    class Options(Options, frozen=True):
        near: Distance = 10.0
        leg: Period = 1.0
        spread: Angle = 70.0

    traits = frozenset({COMMITS, TELLS})

    def __init__(self, options: NearFeint.Options, rng: np.random.Generator) -> None:
        self.options = options
        self.side = 1.0 if rng.random() < 0.5 else -1.0
        self.next_leg = -math.inf
        self.committed_at: float | None = None
        self.events: list[str] = []

    def decide(self, now, me, screen, situation):
        shown = [screen.reports[o].position for o in situation.opponents if o in screen.reports]
        nearest = min((float(np.hypot(*(p - me))) for p in shown), default=math.inf)
        if self.committed_at is None and shown and nearest > self.options.near:
            self.committed_at = now
            self.events.append(f"commits with the defender shown {nearest:.1f} m away")
        if self.committed_at is not None:
            return screen.heading if screen.heading is not None else situation.navigator.toward(situation.goal, me)
        if now >= self.next_leg:
            self.side = -self.side
            self.next_leg = now + self.options.leg
        home = situation.navigator.toward(situation.goal, me)
        if home is None:
            return None
        turn = self.side * math.radians(self.options.spread)
        c, s = math.cos(turn), math.sin(turn)
        return np.array([c * home[0] - s * home[1], s * home[0] + c * home[1]])
