"""A person's real phone, as an agent: its browser page is the GPS, compass and screen.

The page (``agents/human/page``) sends what the phone's Geolocation API
measured; ``report`` turns each into a ``Fix`` through the same types and
codec checks as any fix on the bus, and a bad one is dropped, counted by
reason, and never sent. The fixes go out on the next tick. What comes back
from the ground station goes on the same ``Display`` the emulated phone
uses, and ``view`` is that screen as the page draws it: map metres, ages
in seconds at ``now``, the game's phase and verdict, and each report's
predicted position and 95 % ellipse where calibrated guidance sent them.

No socket here: the bridge (``browser_bridge``) carries the page's
messages in and the views out.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Annotated

import msgspec
import numpy as np
from shapely.geometry import MultiPolygon, Polygon

from bearcat.agents.human.phone import Display
from bearcat.agents.protocol import Send
from bearcat.bus import keys
from bearcat.bus.codec import Refused, decode, encode
from bearcat.bus.messages import Control, Fix, GameState, Guidance, Heading, Latitude, Longitude, Message, Metres
from bearcat.maps import Map
from bearcat.validation import Invalid, convert

TICK = 0.1  # s between the sends of what the page reported
HELD = 20  # fixes held for the next tick at most: a page that floods loses the oldest
AGE_LIMIT = 60_000.0  # ms: a position the phone measured longer ago than this is not a fix
SIGMA_PER_95 = 1.0 / math.sqrt(-2.0 * math.log(0.05))
"""A browser's accuracy is the radius holding the position with 95 %
probability (W3C Geolocation); a fix's is the error per axis, one sigma of a
circular Gaussian, whose 95 % radius is 2.448 sigma."""


class PageFix(msgspec.Struct, forbid_unknown_fields=True):
    """What the page sends for each position the phone's Geolocation API gave:
    ``age`` is how long ago it was measured (milliseconds, on the phone's own
    clock, so the two clocks need not agree), ``accuracy`` the radius the
    browser reports (95 %), ``heading`` the compass (None: not known)."""

    lat: Latitude
    lon: Longitude
    accuracy: Metres | None = None
    heading: Heading | None = None
    age: Annotated[float, msgspec.Meta(ge=0.0, le=AGE_LIMIT)] = 0.0


class PagePhone:
    """Agent ``agent``'s real phone in ``game`` on ``game_map``."""

    role = "phone"
    watches: tuple[str, ...] = ()
    period = TICK

    def __init__(self, game: str, agent: str, game_map: Map) -> None:
        self.game = game
        self.name = keys.check_name(agent, "agent")
        self.map = game_map
        self.display = Display(game_map)
        self.subscriptions = (keys.guidance(game, agent), keys.state(game), keys.control(game))
        self.drops: Counter[str] = Counter()
        self.state: GameState | None = None
        self.last_fix: Fix | None = None
        self.seq = 0
        self._held: list[Fix] = []

    # ------------------------------------------------------------------ the page

    def report(self, data: object, now: float) -> str | None:
        """Take what the page measured; why it was dropped, None if it will be sent."""
        try:
            page = convert(data, PageFix)
            fix = Fix(
                agent=self.name,
                seq=self.seq + 1,
                t=max(now - page.age / 1000.0, 0.0),
                lat=page.lat,
                lon=page.lon,
                heading=page.heading,
                accuracy=None if page.accuracy is None else page.accuracy * SIGMA_PER_95,
            )
            key = keys.fix(self.game, self.name)
            checked = decode(encode(fix), key)  # what any receiver checks, checked before it leaves
            assert isinstance(checked, Fix)  # a fix key carries only fixes
            fix = checked
        except (Invalid, Refused, ValueError, TypeError) as exc:
            reason = str(exc).split(":")[0] if isinstance(exc, Invalid) else type(exc).__name__
            self.drops[reason] += 1
            return f"fix dropped: {exc}"
        self.seq += 1
        self._held = [*self._held, fix][-HELD:]
        self.last_fix = fix
        return None

    def view(self, now: float) -> dict:
        """The screen as the page draws it, at ``now``."""
        s = self.display.screen
        own = None
        if self.last_fix is not None:
            x, y = self.map.to_local(self.last_fix.lat, self.last_fix.lon)
            accuracy = None if self.last_fix.accuracy is None else self.last_fix.accuracy / SIGMA_PER_95
            own = {"x": x, "y": y, "accuracy": accuracy, "age": now - self.last_fix.t}
        state = self.state
        return {
            "agent": self.name,
            "phase": "waiting" if state is None else state.phase,
            "winner": None if state is None else state.winner,
            "reason": "" if state is None else state.reason,
            "flag_holder": None if state is None else state.flag_holder,
            "guidance_age": None if s.shown_at is None else now - s.shown_at,
            "game": s.game,
            "go": s.go,
            "heading": None if s.heading is None else math.degrees(math.atan2(s.heading[0], s.heading[1])) % 360.0,
            "region": [_points(ring) for ring in s.region],
            "region_of": s.region_of,
            "boundary": [_points(line) for line in s.boundary],
            "value": s.value,
            "worst_case": s.worst_case,
            "uncertain": s.uncertain,
            "note": s.note,
            "reports": [
                {
                    "agent": name,
                    "x": float(seen.position[0]),
                    "y": float(seen.position[1]),
                    "age": now - seen.t,
                    "radius": seen.radius,
                    "predicted": None if seen.predicted is None else [float(v) for v in seen.predicted],
                    "ellipse": _ellipse(seen.ellipse),
                }
                for name, seen in sorted(s.reports.items())
            ],
            "fix": own,
            "dropped": sum(self.drops.values()),
        }

    def map_view(self) -> dict:
        """The map as the page draws it: bounds, buildings and regions, in map metres."""
        m = self.map
        return {
            "name": m.name,
            "bounds": list(m.bounds),
            "obstacles": [_points(np.asarray(o.exterior.coords)) for o in m.obstacles],
            "regions": {r.name: _points(np.asarray(_outline(r.geometry).exterior.coords)) for r in m.regions.values()},
        }

    # ------------------------------------------------------------------ the agent protocol

    def start(self, now: float) -> list[Send]:
        return self.tick(now)

    def handle(self, key: str, message: Message, now: float) -> list[Send]:
        if isinstance(message, Guidance):
            self.display.show(message, now)
        elif isinstance(message, GameState):
            if self.state is None or message.seq >= self.state.seq:
                self.state = message
        elif isinstance(message, Control):
            pass  # the referee's state says what a command did
        return []

    def tick(self, now: float) -> list[Send]:
        held, self._held = self._held, []
        return [Send(keys.fix(self.game, self.name), fix) for fix in held]

    def peer(self, key: str, alive: bool, now: float) -> list[Send]:
        return []


def _outline(geometry: Polygon | MultiPolygon) -> Polygon:
    """The one polygon the page draws for a region: the region, or its largest part."""
    return geometry if isinstance(geometry, Polygon) else max(geometry.geoms, key=lambda part: part.area)


def _ellipse(ellipse: tuple[float, float, float] | None) -> list[float] | None:
    """A sighting's 95 % ellipse as the page draws it: semi-major and
    semi-minor axes in metres, the major axis's bearing in degrees clockwise
    from north, as on the wire (the page turns it to the canvas's angle)."""
    if ellipse is None:
        return None
    major, minor, bearing = ellipse
    return [major, minor, math.degrees(bearing) % 180.0]


def _points(points) -> list[list[float]]:
    return [[round(float(x), 2), round(float(y), 2)] for x, y in np.asarray(points, float).reshape(-1, 2)]
