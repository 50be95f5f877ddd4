"""How a simulated person decides where to go, from what their phone shows.

Every behaviour reads the same inputs a person in the field had: their own
position (people know where they stand), the phase of the game, and the
phone's ``Screen`` (opponents as last reported, with the reports' ages; the
opponent's winning region; the heading ring; go / no-go). It returns a
direction (east, north) or None to stand still.

- ``follow-guidance``: walk the displayed heading.
- ``direct`` (unaided): an attacker goes for its goal along the shortest
  path; a defender places itself between the attacker and the return region,
  at the first point of the attacker's straight run home it can reach first.
- ``fake-out`` (thesis 3.5.1): while the display says the defender wins,
  move erratically away from the goal; once it shows the defender outside
  its winning region, follow the heading.
- ``go-no-go`` (thesis 3.5.2): hold at a point near cover until the display
  says go with opponent data fresher than a threshold, then commit to the
  heading for good.
- ``waypoints``: visit points in turn (and loop).
- ``keyboard``: arrow keys or WASD set the direction; the runtime feeds keys.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
import shapely.ops

from agents.human.phone import Screen
from agents.navigation import Navigator

ARRIVED = 1.0  # metres: close enough to a waypoint or hold point


@dataclass(frozen=True)
class Situation:
    """What a behaviour may know besides its screen: who it is, its team and
    opponents, and the regions the rules name (shapely, map metres)."""

    agent: str
    team: str
    opponents: tuple[str, ...]
    goal: object  # where this agent is heading in the current phase (attackers)
    forbidden: object  # where this agent may not go (defenders: flag and return regions)
    navigator: Navigator


class FollowGuidance:
    name = "follow-guidance"

    def decide(self, now: float, me: np.ndarray, screen: Screen, situation: Situation):
        return screen.heading


class Direct:
    name = "direct"

    def decide(self, now, me, screen, situation):
        if situation.team in ("attacker", "evader"):
            return situation.navigator.toward(situation.goal, me)
        target = _nearest_opponent(me, screen, situation)
        if target is None:
            return None
        return _toward(me, _blocking_point(me, target, situation))


class FakeOut:
    """The attacker's fake-out; ``turn_every`` seconds between erratic turns
    spread up to ``spread`` degrees either side of straight away from the goal."""

    name = "fake-out"

    def __init__(self, rng: np.random.Generator, turn_every: float = 1.5, spread: float = 60.0) -> None:
        self.rng = rng
        self.turn_every = turn_every
        self.spread = math.radians(spread)
        self._next_turn = -math.inf
        self._offset = 0.0
        self.faking = True

    def decide(self, now, me, screen, situation):
        defender = _nearest_opponent(me, screen, situation)
        self.faking = defender is not None and screen.region_of is not None and screen.in_region(defender)
        if not self.faking:
            return screen.heading
        if now >= self._next_turn:
            self._offset = self.rng.uniform(-self.spread, self.spread)
            self._next_turn = now + self.turn_every * self.rng.uniform(0.5, 1.5)
        away = me - _nearest_point(situation.goal, me)
        base = math.atan2(away[0], away[1])
        bearing = base + self._offset
        return np.array([math.sin(bearing), math.cos(bearing)])


class GoNoGo:
    """Hold at ``hold`` until go with every opponent's report younger than
    ``fresh`` seconds; then commit. ``committed_at`` records when."""

    name = "go-no-go"

    def __init__(self, hold, fresh: float = 2.0) -> None:
        self.hold = np.asarray(hold, float)
        self.fresh = float(fresh)
        self.committed_at: float | None = None

    def decide(self, now, me, screen, situation):
        if self.committed_at is None:
            fresh = all(screen.age(o, now) <= self.fresh for o in situation.opponents)
            if screen.go and fresh and screen.heading is not None:
                self.committed_at = now
        if self.committed_at is not None:
            return screen.heading if screen.heading is not None else situation.navigator.toward(situation.goal, me)
        if np.hypot(*(self.hold - me)) <= ARRIVED:
            return None
        return situation.navigator.toward(tuple(self.hold), me)


class Waypoints:
    name = "waypoints"

    def __init__(self, points, loop: bool = False) -> None:
        self.points = [np.asarray(p, float) for p in points]
        self.loop = loop
        self.index = 0

    def decide(self, now, me, screen, situation):
        if self.index >= len(self.points):
            return None
        if np.hypot(*(self.points[self.index] - me)) <= ARRIVED:
            self.index += 1
            if self.index == len(self.points) and self.loop:
                self.index = 0
            if self.index >= len(self.points):
                return None
        return situation.navigator.toward(tuple(self.points[self.index]), me)


KEYS = {
    "up": (0.0, 1.0), "w": (0.0, 1.0), "down": (0.0, -1.0), "s": (0.0, -1.0),
    "left": (-1.0, 0.0), "a": (-1.0, 0.0), "right": (1.0, 0.0), "d": (1.0, 0.0),
    "space": None, "x": None,
}  # fmt: skip


class Keyboard:
    """Direction from keys: a key sets it until another key (space or x stops)."""

    name = "keyboard"

    def __init__(self) -> None:
        self.direction: np.ndarray | None = None

    def press(self, key: str) -> bool:
        """Take a key name (``up``, ``w``, ``space``, ...); False for keys it ignores."""
        if key not in KEYS:
            return False
        self.direction = None if KEYS[key] is None else np.array(KEYS[key])
        return True

    def decide(self, now, me, screen, situation):
        return self.direction


def make(name: str, options: dict, rng: np.random.Generator):
    """The behaviour ``name`` with the scenario's ``options``."""
    if name == "follow-guidance":
        return FollowGuidance()
    if name == "direct":
        return Direct()
    if name == "fake-out":
        return FakeOut(rng, **options)
    if name == "go-no-go":
        return GoNoGo(**options)
    if name == "waypoints":
        return Waypoints(**options)
    if name == "keyboard":
        return Keyboard()
    raise ValueError(f"there is no behaviour {name!r}")


# ---------------------------------------------------------------------- geometry


def _toward(me, point) -> np.ndarray | None:
    d = np.asarray(point, float) - me
    n = math.hypot(d[0], d[1])
    return d / n if n > 1e-9 else None


def _nearest_point(geometry, me) -> np.ndarray:
    return np.asarray(shapely.ops.nearest_points(geometry, shapely.Point(me))[0].coords[0])


def _nearest_opponent(me, screen: Screen, situation: Situation) -> np.ndarray | None:
    seen = [screen.reports[o].position for o in situation.opponents if o in screen.reports]
    if not seen:
        return None
    return min(seen, key=lambda q: float(np.hypot(*(q - me))))


def _blocking_point(me, attacker, situation: Situation) -> np.ndarray:
    """The first point of the attacker's straight run to the return region that
    the defender reaches no later than the attacker (both at equal speed: the
    attacker's side of their bisector ends there), kept out of the forbidden
    regions; the attacker's goal point if the whole run is the attacker's."""
    goal = _nearest_point(situation.goal, attacker)
    run = goal - attacker
    length = math.hypot(run[0], run[1])
    target = goal
    if length > 1e-9:
        u = run / length
        # |d - (a + s u)| <= s  <=>  s >= |d - a|^2 / (2 u.(d - a)) when u.(d - a) > 0.
        rel = me - attacker
        along = float(u @ rel)
        if along > 0:
            s = float(rel @ rel) / (2 * along)
            if s <= length:
                target = attacker + s * u
    forbidden = situation.forbidden
    if forbidden is not None and forbidden.covers(shapely.Point(target)):
        # Stop short of where the run enters the forbidden region.
        inside = shapely.LineString([attacker, target]).intersection(forbidden)
        entry = np.asarray(shapely.ops.nearest_points(inside, shapely.Point(attacker))[0].coords[0])
        back = attacker - entry
        n = math.hypot(back[0], back[1])
        target = entry + (0.5 * back / n if n > 0.5 else back)
    return target
