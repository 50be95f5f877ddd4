"""The body that carries a phone: where a person really is and how they move.

A person follows an intended direction with a reaction delay (the intent
formed at ``t`` reaches the legs at ``t + reaction``) and a heading error
that wanders rather than jitters (a first-order Gauss-Markov process with a
few seconds' correlation: people drift off a displayed bearing and correct,
they do not shake). Speed is the scenario's top speed times the terrain
factor of the map where the person stands. Obstacles and the area's edge
cannot be entered: a step that would end in one slides along whichever axis
is still free, or is not taken; so is one into a region the rules forbid
this person (a defender's flag and return regions).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
import shapely

from bearcat.maps import Map

HEADING_TAU = 3.0  # s, correlation time of the heading error


class Walker:
    """A walking or running person on ``game_map``, starting at ``start`` (metres)."""

    def __init__(
        self,
        game_map: Map,
        start,
        *,
        speed: float,
        reaction: float = 0.4,
        heading_error: float = 0.0,
        keep_out=None,
        rng: np.random.Generator,
    ) -> None:
        self.map = game_map
        self.position = np.array(start, dtype=float)
        self.speed = float(speed)
        self.reaction = float(reaction)
        self.heading_sigma = math.radians(heading_error)
        self.rng = rng
        self.velocity = np.zeros(2)
        self._intents: deque[tuple[float, np.ndarray | None]] = deque([(-math.inf, None)])
        self._error = rng.normal(0.0, self.heading_sigma) if self.heading_sigma > 0 else 0.0
        # Where the person may step: the free space, less any region the rules
        # forbid them (they know better than to walk into it).
        self._free = game_map.free_space if keep_out is None else game_map.free_space.difference(keep_out)
        shapely.prepare(self._free)
        self._zones = [(z.geometry, z.speed) for z in game_map.zones]
        for geometry, _ in self._zones:
            shapely.prepare(geometry)

    @property
    def heading(self) -> float | None:
        """Direction of travel, radians clockwise from north (None when standing)."""
        if not self.velocity.any():
            return None
        return math.atan2(self.velocity[0], self.velocity[1]) % (2 * math.pi)

    def intend(self, now: float, direction) -> None:
        """The person decides at ``now`` to go along ``direction`` (east, north),
        at full speed, or to stop (None or zero)."""
        d = None
        if direction is not None:
            d = np.asarray(direction, dtype=float)
            n = math.hypot(d[0], d[1])
            d = d / n if n > 1e-12 else None
        self._intents.append((now, d))

    def step(self, now: float, dt: float) -> np.ndarray:
        """Move from ``now`` to ``now + dt``; the new position."""
        while len(self._intents) > 1 and self._intents[1][0] <= now - self.reaction:
            self._intents.popleft()
        intent = self._intents[0][1]
        self._wander(dt)
        if intent is None:
            self.velocity = np.zeros(2)
            return self.position
        c, s = math.cos(self._error), math.sin(self._error)
        # Rotating clockwise by the error (a bearing error, positive to the right).
        d = np.array([c * intent[0] + s * intent[1], -s * intent[0] + c * intent[1]])
        step = d * self.speed * self.terrain(self.position) * dt
        new = self._slide(step)
        self.velocity = (new - self.position) / dt if dt > 0 else np.zeros(2)
        self.position = new
        return new

    def terrain(self, point) -> float:
        """The map's speed factor at ``point``: the last zone covering it, else the area's."""
        factor = self.map.area_speed
        for geometry, speed in self._zones:
            if shapely.contains_xy(geometry, point[0], point[1]):
                factor = speed
        return factor

    def _slide(self, step: np.ndarray) -> np.ndarray:
        p = self.position
        for candidate in (p + step, p + (step[0], 0.0), p + (0.0, step[1])):
            if shapely.intersects_xy(self._free, candidate[0], candidate[1]):
                return candidate
        return p.copy()

    def _wander(self, dt: float) -> None:
        if self.heading_sigma > 0 and dt > 0:
            a = math.exp(-dt / HEADING_TAU)
            self._error = a * self._error + self.heading_sigma * math.sqrt(1 - a * a) * self.rng.normal()
