"""The built-in behaviours: how the thesis's people decided where to go.

Each is an entry of ``behaviour.BEHAVIOURS`` exactly as a user's own is
(see ``behaviour.Behaviour``), with its options type:

- ``follow-guidance``: walk the displayed heading.
- ``direct`` (unaided): an attacker goes for its goal along the shortest
  path; a defender places itself between the attacker and the return region,
  partway along the attacker's straight run there, and walks round the
  regions it may not enter.
- ``fake-out`` (thesis 3.5.1): while the display says the defender wins,
  move erratically away from the goal; once it shows the defender outside
  its winning region, follow the heading.
- ``go-no-go`` (thesis 3.5.2): hold at a point near cover until the display
  says go with opponent data fresher than a threshold, then commit to the
  heading for good.
- ``waypoints``: visit points in turn (and loop).
- ``patrol`` (thesis 6.2.4): walk a route round and round, or wander
  between its points at random, while no opponent is in sight; play
  ``direct`` against one seen in the last ``memory`` seconds.
- ``keyboard``: arrow keys or WASD set the direction; the runtime feeds keys.
"""

from __future__ import annotations

import math
from typing import Annotated, ClassVar

import numpy as np
import shapely
import shapely.ops
from msgspec import Meta

from bearcat.agents.human.behaviour import COMMITS, TAKES_KEYS, Behaviour, Situation
from bearcat.agents.human.phone import Screen
from bearcat.agents.options import Angle, Distance, Lag, Memory, NoOptions, Options, Period, Point, Route, Share

ARRIVED = 1.0  # metres: close enough to a waypoint or hold point


class UnaidedOptions(Options, frozen=True):
    standoff: Distance = 6.0
    share: Share = 0.5
    lead: Lag = 1.5


class FakeOutOptions(Options, frozen=True):
    turn_every: Annotated[float, Meta(gt=0.0, le=600.0, extra={"unit": "s"})] = 1.5
    spread: Angle = 100.0
    margin: Distance = 0.0


class GoNoGoOptions(Options, frozen=True):
    hold: Point
    fresh: Period = 2.0
    margin: Distance = 0.0
    flee: Distance = 0.0

    def places(self):
        return (("hold", self.hold),)


class WaypointsOptions(Options, frozen=True):
    points: Route
    loop: bool = False

    def places(self):
        return tuple((f"points[{j}]", p) for j, p in enumerate(self.points))


class PatrolOptions(UnaidedOptions, kw_only=True, frozen=True):
    points: Route
    memory: Memory = 5.0
    wander: bool = False

    def places(self):
        return tuple((f"points[{j}]", p) for j, p in enumerate(self.points))


class FollowGuidance(Behaviour):
    """Walk the displayed heading, but not into a region one may not enter."""

    def decide(self, now: float, me: np.ndarray, screen: Screen, situation: Situation):
        return _around(me, screen.heading, situation.forbidden)


class Unaided(Behaviour):
    """Unaided play: run for the goal, block the attacker's run, flee or chase.

    An attacker goes for its goal
    along the shortest path; an evader runs from the pursuers it sees,
    nearest first; a pursuer runs straight at the evader.
    A defender marks the attacker as displayed, anticipating it: it takes
    the attacker ``lead`` seconds ahead on its course (read from its last two
    displayed positions) and keeps to the straight run from there to the
    attacker's goal, ``standoff`` metres in front (or ``share`` of the way,
    if that is nearer), walking round the regions it may not enter. It is
    how a person blocks without a solver, and what a feint exploits: the
    mark lags the display's age and the person's reaction, and a reversal
    leaves it committed to the wrong side."""

    Options = UnaidedOptions

    def __init__(self, options: UnaidedOptions, rng: np.random.Generator) -> None:
        self.standoff = options.standoff
        self.share = options.share
        self.lead = options.lead
        self._seen: dict[str, tuple[float, np.ndarray]] = {}
        self._course: dict[str, np.ndarray] = {}

    def decide(self, now, me, screen, situation):
        if situation.team == "attacker":
            return situation.navigator.toward(situation.goal, me)
        if situation.team == "evader":
            return _flee(me, screen, situation)
        if situation.team == "pursuer":
            evader = _nearest_opponent(me, screen, situation)
            return None if evader is None else _toward(me, evader.position)
        attacker = _nearest_opponent(me, screen, situation)
        if attacker is None:
            return None
        a = attacker.position + self.lead * self._track(attacker, situation)
        run = _nearest_point(situation.goal, a) - a
        length = float(np.hypot(*run))
        target = a if length < 1e-9 else a + min(self.standoff, self.share * length) * run / length
        if np.hypot(*(target - me)) < 0.5:
            return None
        return _around(me, _toward(me, target), situation.forbidden)

    def _track(self, attacker, situation) -> np.ndarray:
        """The attacker's velocity from its last two displayed fixes (zero until known)."""
        key = min(situation.opponents)
        last = self._seen.get(key)
        if last is None or attacker.t > last[0]:
            if last is not None and attacker.t - last[0] < 5.0:
                self._course[key] = (attacker.position - last[1]) / (attacker.t - last[0])
            self._seen[key] = (attacker.t, attacker.position)
        return self._course.get(key, np.zeros(2))


class FakeOut(Behaviour):
    """The attacker's fake-out (thesis 3.5.1): feint, then go home for good.

    While the display shows the defender in its
    winning region, the attacker feints: it runs across the field, to one
    side then the other, each leg ``turn_every`` seconds give or take half,
    at ``spread`` degrees from the line to its goal give or take 30 (more
    than 90: drifting back, less: pressing forward). Once the display shows
    the defender outside its region, by at least ``margin`` metres of the
    solver's value, it follows the heading home for good (``committed_at``
    records when)."""

    Options = FakeOutOptions
    traits = frozenset({COMMITS})

    def __init__(self, options: FakeOutOptions, rng: np.random.Generator) -> None:
        self.rng = rng
        self.margin = options.margin
        self.turn_every = options.turn_every
        self.spread = math.radians(options.spread)
        self._next_turn = -math.inf
        self._side = 1.0 if rng.random() < 0.5 else -1.0
        self._offset = 0.0
        self.committed_at: float | None = None

    def decide(self, now, me, screen, situation):
        if self.committed_at is None:
            defender = _nearest_opponent(me, screen, situation)
            clear = screen.value is not None and screen.value <= -self.margin
            if (
                defender is not None
                and screen.region_of is not None
                and not screen.in_region(defender.position)
                and clear
            ):
                self.committed_at = now
        if self.committed_at is not None:
            return screen.heading
        if now >= self._next_turn:
            self._side = -self._side
            self._offset = self._side * (self.spread + self.rng.uniform(-math.pi / 6, math.pi / 6))
            self._next_turn = now + self.turn_every * self.rng.uniform(0.5, 1.5)
        home = _nearest_point(situation.goal, me) - me
        bearing = math.atan2(home[0], home[1]) + self._offset
        return np.array([math.sin(bearing), math.cos(bearing)])


class GoNoGo(Behaviour):
    """Hold near cover until the display says go on fresh reports (thesis 3.5.2), then commit.

    Hold at ``hold`` until the display says go, by at least ``margin``
    metres of the solver's value, with every opponent's report younger than
    ``fresh`` seconds (or a go that holds wherever an unseen opponent may
    be); then commit for good. ``committed_at`` records when.
    Until then, an opponent shown within ``flee`` metres with a fresh report
    is run from (0: stand one's ground)."""

    Options = GoNoGoOptions
    traits = frozenset({COMMITS})

    def __init__(self, options: GoNoGoOptions, rng: np.random.Generator) -> None:
        self.hold = np.asarray(options.hold, float)
        self.fresh = float(options.fresh)
        self.margin = float(options.margin)
        self.flee = float(options.flee)
        self.committed_at: float | None = None

    def decide(self, now, me, screen, situation):
        if self.committed_at is None:
            fresh = screen.worst_case or all(screen.age(o, now) <= self.fresh for o in situation.opponents)
            clear = screen.value is not None and screen.value <= -self.margin
            if screen.go and clear and fresh and screen.heading is not None:
                self.committed_at = now
        if self.committed_at is not None:
            return screen.heading if screen.heading is not None else situation.navigator.toward(situation.goal, me)
        near = [
            o
            for o in situation.opponents
            if screen.age(o, now) <= self.fresh and np.hypot(*(screen.reports[o].position - me)) <= self.flee
        ]
        if near:
            return _flee(me, screen, situation)
        if np.hypot(*(self.hold - me)) <= ARRIVED:
            return None
        return situation.navigator.toward(tuple(self.hold), me)


class Waypoints(Behaviour):
    """Visit ``points`` in turn, and with ``loop`` start again."""

    Options = WaypointsOptions

    def __init__(self, options: WaypointsOptions, rng: np.random.Generator) -> None:
        self.points = [np.asarray(p, float) for p in options.points]
        self.loop = options.loop
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


class Patrol(Behaviour):
    """Walk a route until an opponent is seen, then play ``direct``.

    Walk the ``points`` in turn (or, with ``wander``, each next one drawn
    at random among the others, so the route cannot be learnt) until an
    opponent is on the screen; then play unaided (``direct``)."""

    Options = PatrolOptions

    def __init__(self, options: PatrolOptions, rng: np.random.Generator) -> None:
        self.points = [np.asarray(p, float) for p in options.points]
        self.rng = rng
        self.wander = options.wander
        self.unaided = Unaided(options, rng)
        self.memory = float(options.memory)
        self.index = int(rng.integers(len(self.points))) if self.wander else 0

    def decide(self, now, me, screen, situation):
        if any(screen.age(o, now) <= self.memory for o in situation.opponents):
            return self.unaided.decide(now, me, screen, situation)
        if np.hypot(*(self.points[self.index] - me)) <= ARRIVED:
            self.index = self._next()
        return situation.navigator.toward(tuple(self.points[self.index]), me)

    def _next(self) -> int:
        if not self.wander or len(self.points) == 1:
            return (self.index + 1) % len(self.points)
        others = [k for k in range(len(self.points)) if k != self.index]
        return int(self.rng.choice(others))


KEY_DIRECTIONS = {
    "up": (0.0, 1.0),
    "w": (0.0, 1.0),
    "down": (0.0, -1.0),
    "s": (0.0, -1.0),
    "left": (-1.0, 0.0),
    "a": (-1.0, 0.0),
    "right": (1.0, 0.0),
    "d": (1.0, 0.0),
    "space": None,
    "x": None,
}


class Keyboard(Behaviour):
    """Walk where the keys say: arrows or WASD set the direction until another key; space or x stops."""

    traits: ClassVar[frozenset[str]] = frozenset({TAKES_KEYS})

    def __init__(self, options: NoOptions, rng: np.random.Generator) -> None:
        self.direction: np.ndarray | None = None

    def press(self, key: str) -> bool:
        """Take a key name (``up``, ``w``, ``space``, ...); False for keys it ignores."""
        if key not in KEY_DIRECTIONS:
            return False
        self.direction = None if KEY_DIRECTIONS[key] is None else np.array(KEY_DIRECTIONS[key])
        return True

    def decide(self, now, me, screen, situation):
        return self.direction


BUILTINS: dict[str, type] = {
    "follow-guidance": FollowGuidance,
    "direct": Unaided,
    "fake-out": FakeOut,
    "go-no-go": GoNoGo,
    "waypoints": Waypoints,
    "patrol": Patrol,
    "keyboard": Keyboard,
}
"""The built-in entries of ``behaviour.BEHAVIOURS``, by the names scenarios give them."""


# ---------------------------------------------------------------------- geometry


def _toward(me, point) -> np.ndarray | None:
    d = np.asarray(point, float) - me
    n = math.hypot(d[0], d[1])
    return d / n if n > 1e-9 else None


def _nearest_point(geometry, me) -> np.ndarray:
    return np.asarray(shapely.ops.nearest_points(geometry, shapely.Point(me))[0].coords[0])


def _nearest_opponent(me, screen: Screen, situation: Situation):
    """The opponent's ``Sighting`` nearest ``me`` on the screen, None if none is shown."""
    seen = [screen.reports[o] for o in situation.opponents if o in screen.reports]
    if not seen:
        return None
    return min(seen, key=lambda q: float(np.hypot(*(q.position - me))))


def _flee(me, screen: Screen, situation: Situation):
    """Away from the displayed pursuers, each weighted by one over its
    distance squared, turned along the field's edge when that is in the way."""
    push = np.zeros(2)
    for o in situation.opponents:
        seen = screen.reports.get(o)
        if seen is not None:
            away = me - seen.position
            push += away / max(float(away @ away), 1e-6)
    if not push.any():
        return None
    area = situation.navigator.area
    d = push / np.hypot(*push)
    if not area.covers(shapely.Point(me + 3.0 * d)):
        # Slide along the edge, to whichever side keeps away from the pursuers.
        tangents = [np.array([-d[1], d[0]]), np.array([d[1], -d[0]])]
        d = max(tangents, key=lambda t: float(t @ push) + (0.0 if area.covers(shapely.Point(me + 3.0 * t)) else -1e9))
    return d


def _around(me, direction, forbidden) -> np.ndarray | None:
    """``direction`` turned by the least angle that keeps the next few metres
    out of ``forbidden`` (a defender walks round the regions it may not enter)."""
    if direction is None or forbidden is None:
        return direction
    for turn in np.radians(np.arange(0, 181, 10)):
        for sign in (1, -1):
            c, s = math.cos(sign * turn), math.sin(sign * turn)
            d = np.array([c * direction[0] - s * direction[1], s * direction[0] + c * direction[1]])
            if not any(shapely.intersects_xy(forbidden, *(me + k * d)) for k in (0.5, 1.0, 2.0)):
                return d
    return None
