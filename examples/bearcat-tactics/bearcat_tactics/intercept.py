"""A defender's phone that points where the attacker can be cut off, not
where the attacker is.

The ground station's tracker of the attacker gives where it is now and
how it moves; the defender, at its top speed, meets it first at the
smallest ``t`` with ``|a + v t - d| = s t``. The phone shows the heading
to that point, and otherwise what the thesis's guidance shows (the
attacker's winning region, the value). When no such point comes within
``horizon`` seconds (the attacker outruns the defender), it points at
where the attacker will be then. An attacker's phone given this method
shows the thesis's guidance unchanged.
"""

from __future__ import annotations

import msgspec
import numpy as np

from bearcat.plugins import TRACKS, Advice, GuidanceMethod, GuidanceView, Lag, Options, bearing


class Intercept(GuidanceMethod):
    """Steer the defender toward the attacker's predicted interception point."""

    traits = frozenset({TRACKS})
    needs = frozenset({"plain"})

    class Options(Options, frozen=True):
        horizon: Lag = 10.0

    def __init__(self, options: Intercept.Options, rng: np.random.Generator) -> None:
        self.horizon = options.horizon

    def advise(self, view: GuidanceView) -> Advice:
        shown = view.answers.plain(view)
        me = view.position(view.agent)
        believed = [view.belief(who) for who in view.opponents]
        if view.team != "defender" or me is None or any(b is None for b in believed):
            return shown
        attacker = min(believed, key=lambda b: float(np.hypot(*(b.position - me))))
        t = meeting_time(attacker.position - me, attacker.velocity, view.speeds[view.agent], self.horizon)
        aim = attacker.position + attacker.velocity * t - me
        if np.hypot(*aim) < 1e-6:
            return shown
        return msgspec.structs.replace(
            shown, heading=bearing(float(aim[0]), float(aim[1])), note=f"cut off in {t:.1f} s"
        )


def meeting_time(offset: np.ndarray, velocity: np.ndarray, speed: float, horizon: float) -> float:
    """The first ``t`` in [0, ``horizon``] at which a pursuer of ``speed``
    from the origin can be where a target at ``offset`` moving at
    ``velocity`` is: the least non-negative root of
    ``(v.v - s^2) t^2 + 2 (r.v) t + r.r = 0``; ``horizon`` if none is sooner."""
    a = float(velocity @ velocity) - speed**2
    b = 2.0 * float(offset @ velocity)
    c = float(offset @ offset)
    if abs(a) < 1e-12:
        roots = [-c / b] if b < 0 else []
    else:
        disc = b * b - 4.0 * a * c
        roots = [] if disc < 0 else [(-b - np.sqrt(disc)) / (2 * a), (-b + np.sqrt(disc)) / (2 * a)]
    ahead = [float(t) for t in roots if 0.0 <= t <= horizon]
    return min(ahead, default=horizon)
