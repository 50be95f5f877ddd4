"""What an advisor answers from: the latest fix of each agent, in map metres.

Fixes are what the network delivered, GPS error included, so one may put an
agent inside a building or off the map; ``nearest_inside`` moves it to the
nearest free point before a solver is asked, as a person's phone would still
show them somewhere. A fix is also stale: ``Uncertainty`` bounds where its agent
may be by now, and a tracker per agent (``Trackers``), where calibrated
guidance asks for one, estimates where it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
import shapely.ops

from bearcat.agents.ground_station.tracker import Belief, Trackers
from bearcat.bus.messages import Fix, Report
from bearcat.maps import Map

DEFAULT_CONFIDENCE = 0.95


def error_radius(sigma: float | None, confidence: float = DEFAULT_CONFIDENCE) -> float:
    """The radius holding a fix's true position with probability
    ``confidence``, for a circular two-axis Gaussian error of ``sigma``
    metres per axis (2.448 sigma at 95 %; None: the sender gave no accuracy,
    taken as exact)."""
    return math.sqrt(-2.0 * math.log1p(-confidence)) * float(sigma or 0.0)


@dataclass(frozen=True)
class Uncertainty:
    """How far each agent may be from its last fix: its top speed (``speeds``)
    times the fix's age, plus the fix's error radius at ``confidence`` (0:
    the age alone)."""

    speeds: dict
    confidence: float = DEFAULT_CONFIDENCE

    def radius(self, agent: str, age: float, sigma: float | None) -> float | None:
        """The radius for ``agent``'s fix of ``age`` seconds and per-axis error
        ``sigma`` (a fix's ``accuracy``); None for an agent whose top speed is not known."""
        speed = self.speeds.get(agent)
        if speed is None:
            return None
        return max(float(age), 0.0) * float(speed) + error_radius(sigma, self.confidence)


class LatestFixes:
    """The latest fix per agent, in map metres, ignoring fixes older than the
    one held; and, with ``trackers``, every fix given to them as well (a late
    one is evidence too), so that each agent is also believed somewhere now."""

    def __init__(self, game_map: Map, trackers: Trackers | None = None) -> None:
        self.map = game_map
        self.trackers = trackers
        self.latest: dict[str, tuple[np.ndarray, float, Fix]] = {}
        self._believed: tuple[float, int, dict[str, Belief]] = (-math.inf, -1, {})
        self._taken = 0

    def take(self, fix: Fix) -> bool:
        """Keep ``fix`` if it is newer than the one held; whether it was."""
        if self.trackers is not None and self.trackers.take(fix):
            self._taken += 1
        held = self.latest.get(fix.agent)
        if held is None or fix.t > held[1]:
            self.latest[fix.agent] = (np.array(self.map.to_local(fix.lat, fix.lon)), fix.t, fix)
            return True
        return False

    def beliefs(self, now: float) -> dict[str, Belief]:
        """Where the trackers believe each agent is at ``now`` (none without
        trackers); predicted once per moment and fix, however many phones
        are answered then."""
        if self.trackers is None:
            return {}
        t, taken, held = self._believed
        if t != now or taken != self._taken:
            held = self.trackers.predict(now)
            self._believed = (now, self._taken, held)
        return held

    def reports(self, now: float, uncertainty: Uncertainty | None = None) -> list[Report]:
        """Every agent as last reported, with the radius it may be in by
        ``now`` where ``uncertainty`` knows it, and where its tracker
        believes it is then, with the 95 % ellipse of that belief."""
        beliefs = self.beliefs(now)
        out = []
        for agent, (_, t, f) in self.latest.items():
            radius = None if uncertainty is None else uncertainty.radius(agent, now - t, f.accuracy)
            belief = beliefs.get(agent)
            predicted = ellipse = None
            if belief is not None:
                lat, lon = self.map.to_geodetic(*belief.position)
                predicted = (round(float(lon), 7), round(float(lat), 7))
                major, minor, axis = belief.ellipse()
                ellipse = (round(min(major, 1e7), 2), round(min(minor, 1e7), 2), round(axis, 1) % 180.0)
            out.append(
                Report(
                    agent,
                    f.t,
                    f.lat,
                    f.lon,
                    radius=None if radius is None else round(min(radius, 1e7), 2),
                    predicted=predicted,
                    ellipse=ellipse,
                )
            )
        return out


def nearest_inside(inside, point) -> np.ndarray:
    """The point of the shapely geometry ``inside`` nearest ``point`` (map metres)."""
    return np.asarray(shapely.ops.nearest_points(inside, shapely.Point(point))[0].coords[0])
