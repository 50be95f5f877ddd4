"""Closed-loop play of the many-pursuers-one-evader game of thesis 5.1: every
agent picks a heading from the current positions, all move one time step at
full speed, and the referee checks capture.

Capture is checked over the whole step, not only at its end: within a step
every agent moves in a straight line, so the pursuer-evader separation is a
quadratic in time whose minimum is found exactly. Two agents closing at
twice the top speed cover ``2 v dt`` per step, and with ``dt`` near the
capture radius a check at the step ends alone would let them pass through
each other (the remark at the end of thesis 5.3.1).

Agents never enter blocked places: a move that would end in one slides
along whichever axis is still free, or is not made.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from bearcat.solvers.errors import InputError, non_negative, positive

__all__ = ["Chase", "EvaderPolicy", "PursuitStrategy", "first_contact", "pursue"]


class PursuitStrategy(Protocol):
    def headings(self, evader: np.ndarray, pursuers: np.ndarray) -> np.ndarray:
        """(N, 2) unit headings, a zero row to stand still."""


class EvaderPolicy(Protocol):
    def heading(self, evader: np.ndarray, pursuers: np.ndarray) -> np.ndarray:
        """(2,) unit heading, zeros to stand still."""


@dataclass(frozen=True)
class Chase:
    """Tracks at ``times``: ``evader`` (k, 2) and ``pursuers`` (k, N, 2).
    ``capture_time`` is when the first pursuer came within the capture
    radius (interpolated within the step), or None if the evader lasted
    ``max_time``; ``captor`` is that pursuer's index."""

    times: np.ndarray
    evader: np.ndarray
    pursuers: np.ndarray
    capture_time: float | None
    captor: int | None

    @property
    def captured(self) -> bool:
        return self.capture_time is not None


def first_contact(e0, e1, p0, p1, radius: float) -> float | None:
    """The fraction of the step in ``[0, 1]`` at which an evader moving from
    ``e0`` to ``e1`` and a pursuer moving from ``p0`` to ``p1``, both in
    straight lines at constant speed, first come within ``radius``; None if
    they never do during the step."""
    r0 = np.asarray(e0, float) - np.asarray(p0, float)
    dr = (np.asarray(e1, float) - np.asarray(p1, float)) - r0
    c = float(r0 @ r0) - radius * radius
    if c <= 0:
        return 0.0
    a, b = float(dr @ dr), 2.0 * float(r0 @ dr)
    if a == 0.0:
        return None
    disc = b * b - 4 * a * c
    if disc < 0:
        return None
    s = (-b - np.sqrt(disc)) / (2 * a)
    return float(s) if 0.0 <= s <= 1.0 else None


def pursue(
    strategy: PursuitStrategy,
    evader_policy: EvaderPolicy,
    evader,
    pursuers,
    *,
    passable: Callable[[np.ndarray], bool],
    dt: float = 0.05,
    capture_radius: float = 0.5,
    evader_speed: float = 1.0,
    pursuer_speeds=1.0,
    max_time: float = 100.0,
) -> Chase:
    """Play until capture or ``max_time``. ``passable(point)`` says whether
    an agent may stand at a point (inside the domain, outside obstacles)."""
    e = np.asarray(evader, float).copy()
    p = np.array(pursuers, float, ndmin=2).copy()
    if e.shape != (2,) or p.ndim != 2 or p.shape[1] != 2 or len(p) == 0:
        raise InputError("the evader must be one point (x, y) and the pursuers a list of points")
    dt = positive(dt, "dt")
    max_time = positive(max_time, "max_time")
    capture_radius = non_negative(capture_radius, "capture radius")
    speeds = np.broadcast_to(np.asarray(pursuer_speeds, float), (len(p),))
    for who, point in (("evader", e), *((f"pursuer {i + 1}", q) for i, q in enumerate(p))):
        if not passable(point):
            raise InputError(f"{who} starts at ({point[0]:.2f}, {point[1]:.2f}), outside the free space")
    times, e_track, p_track = [0.0], [e.copy()], [p.copy()]
    gaps = np.hypot(*(p - e).T)
    if gaps.min() <= capture_radius:
        captor = int(np.argmin(gaps))
        return Chase(np.array(times), np.array(e_track), np.array(p_track), 0.0, captor)
    t = 0.0
    while t < max_time - 1e-12:
        step = min(dt, max_time - t)
        e_next = _move(e, evader_speed * step * _unit(evader_policy.heading(e.copy(), p.copy())), passable)
        headings = np.asarray(strategy.headings(e.copy(), p.copy()), float)
        if headings.shape != p.shape:
            raise InputError(f"the pursuit strategy returned headings of shape {headings.shape} for {len(p)} pursuers")
        p_next = np.array([_move(q, s * step * _unit(h), passable) for q, s, h in zip(p, speeds, headings)])
        contacts = [
            (first_contact(e, e_next, q, q_next, capture_radius), i) for i, (q, q_next) in enumerate(zip(p, p_next))
        ]
        hits = [(s, i) for s, i in contacts if s is not None]
        if hits:
            s, captor = min(hits)
            times.append(t + s * step)
            e_track.append(e + s * (e_next - e))
            p_track.append(p + s * (p_next - p))
            return Chase(np.array(times), np.array(e_track), np.array(p_track), t + s * step, captor)
        e, p, t = e_next, p_next, t + step
        times.append(t)
        e_track.append(e.copy())
        p_track.append(p.copy())
    return Chase(np.array(times), np.array(e_track), np.array(p_track), None, None)


def _unit(h) -> np.ndarray:
    h = np.asarray(h, float)
    if h.shape != (2,) or not np.isfinite(h).all():
        raise InputError(f"a heading must be a finite (east, north) pair, got {h!r}")
    norm = float(np.hypot(*h))
    return h / norm if norm > 1e-12 else np.zeros(2)


def _move(point: np.ndarray, delta: np.ndarray, passable) -> np.ndarray:
    """``point + delta``, or its slide along one axis, or ``point`` itself,
    whichever first lands on free space."""
    for candidate in (point + delta, point + (delta[0], 0.0), point + (0.0, delta[1])):
        if passable(candidate):
            return candidate
    return point.copy()
