"""The phone a person carries: its GPS and compass, and the model of its screen.

Fixes go out at the phone's rate through the profile's GPS error (a
time-correlated bias, worse near buildings, with dropouts) and compass
error, as WGS84 positions. What comes back (guidance from the ground
station) becomes the ``Screen``: the opponent's winning region, the heading
ring, go / no-go, and every agent as last reported with that report's time
and the disk it may be in (with calibrated guidance, also where its tracker
expects it now, inside a 95 % ellipse), so a behaviour or a person reads
exactly what the display shows, stale positions included, and the recorder
can draw it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely

from bearcat.bus.messages import Fix, Guidance
from bearcat.maps import Map
from bearcat.maps.geodesy import compass_degrees
from bearcat.netem.models import CompassError, CompassTrack, GpsError, GpsTrack


@dataclass(frozen=True)
class Sighting:
    """An agent as the screen shows it: where (map metres), the time of the
    fix, and the radius of the disk it may be in by then (None: not known).
    Where calibrated guidance tracks it, ``predicted`` is where its tracker
    believes it is at the guidance's time (map metres) and ``ellipse`` that
    belief's 95 % ellipse: semi-major and semi-minor axes in metres and the
    major axis's bearing in radians clockwise from north (both None where
    the report has no prediction): a fix seconds old says less than where
    the tracker, which has seen the walk so far, expects the agent now."""

    position: np.ndarray
    t: float
    radius: float | None = None
    predicted: np.ndarray | None = None
    ellipse: tuple[float, float, float] | None = None


@dataclass
class Screen:
    """The display: everything is as of the last guidance received (``shown_at``)."""

    shown_at: float | None = None
    computed_at: float | None = None
    game: str = "none"
    heading: np.ndarray | None = None  # unit (east, north), the ring's arrow
    region: list[np.ndarray] = field(default_factory=list)  # opponent's winning region, rings in metres
    region_of: str | None = None
    go: bool | None = None
    value: float | None = None
    worst_case: bool = False  # value and go hold wherever the unseen opponent may be
    uncertain: bool = False  # the answer for where the players may be differs from the one at their reports
    boundary: list[np.ndarray] = field(default_factory=list)
    reports: dict[str, Sighting] = field(default_factory=dict)
    note: str = ""

    def age(self, agent: str, now: float) -> float:
        """Seconds since the fix the screen shows for ``agent`` was taken (inf if none)."""
        seen = self.reports.get(agent)
        return math.inf if seen is None else now - seen.t

    def in_region(self, point) -> bool:
        """Whether ``point`` lies in the displayed region."""
        return any(shapely.Polygon(ring).covers(shapely.Point(point)) for ring in self.region if len(ring) >= 3)


class Phone:
    """Agent ``agent``'s phone on ``game_map``."""

    def __init__(
        self,
        agent: str,
        game_map: Map,
        *,
        gps: GpsError,
        compass: CompassError,
        rng: np.random.Generator,
        fix_rate: float = 1.0,
    ) -> None:
        self.agent = agent
        self.map = game_map
        self.period = 1.0 / fix_rate
        self.gps = GpsTrack(gps, rng)
        self.compass = CompassTrack(compass, rng)
        self.display = Display(game_map)
        self.seq = 0
        self.next_fix = float(rng.uniform(0.0, self.period))  # phones are not in step with each other
        self._buildings = shapely.union_all(game_map.obstacles) if game_map.obstacles else None
        if self._buildings is not None:
            shapely.prepare(self._buildings)
        self._heading = 0.0
        # A GPS fault: ("jump", offset), ("freeze", anything) or ("spoof", position), metres.
        self.lie: tuple[str, tuple[float, float]] | None = None
        self._told: tuple[float, float] | None = None  # the last position a fix reported, in metres

    def fix(self, now: float, position, heading: float | None) -> Fix | None:
        """A fix of the true ``position`` (metres) and ``heading`` (radians from
        north, None when standing) if one is due at ``now``; None if not due or
        the GPS dropped out."""
        if now + 1e-9 < self.next_fix:
            return None
        self.next_fix = max(self.next_fix + self.period, now)
        near = math.inf if self._buildings is None else self._buildings.distance(shapely.Point(position))
        error = self.gps.error(now, near)
        if error is None:
            return None
        if heading is not None:
            self._heading = heading
        x, y = self._reported(np.asarray(position, float) + error)
        lat, lon = self.map.to_geodetic(x, y)
        reading = compass_degrees(self.compass.reading(self._heading))
        self.seq += 1
        return Fix(
            agent=self.agent,
            seq=self.seq,
            t=now,
            lat=lat,
            lon=lon,
            heading=reading,
            accuracy=self.gps.model.horizontal_sigma(near <= self.gps.model.urban_distance),
        )

    def _reported(self, measured) -> tuple[float, float]:
        """Where the fix says the phone is: what it measured, unless its GPS lies."""
        mode, where = self.lie or ("", (0.0, 0.0))
        if mode == "jump":
            measured = measured + np.asarray(where, float)
        elif mode == "spoof":
            measured = np.asarray(where, float)
        elif mode == "freeze" and self._told is not None:
            measured = np.asarray(self._told, float)
        self._told = (float(measured[0]), float(measured[1]))
        return self._told

    def show(self, guidance: Guidance, now: float) -> None:
        """Put a guidance message on the screen (an older one than shown is ignored)."""
        self.display.show(guidance, now)

    @property
    def screen(self) -> Screen:
        return self.display.screen


class Display:
    """What puts guidance on a ``Screen`` of ``game_map``: the emulated phone's
    and the browser phone's alike."""

    def __init__(self, game_map: Map) -> None:
        self.map = game_map
        self.screen = Screen()
        self._region_shown: list = []
        self._region_local: list[np.ndarray] = []
        self._places: dict[tuple[str, str], tuple[tuple[float, float], np.ndarray]] = {}

    def show(self, guidance: Guidance, now: float) -> None:
        """Put ``guidance`` on the screen at ``now`` (an older one than shown is ignored)."""
        s = self.screen
        if s.computed_at is not None and guidance.t < s.computed_at:
            return
        to_local = self._to_local
        s.shown_at, s.computed_at, s.game = now, guidance.t, guidance.game
        s.heading = None if guidance.heading is None else _unit(math.radians(guidance.heading))
        if guidance.region != self._region_shown:  # mostly the same rings, sent ten times a second
            self._region_shown = guidance.region
            self._region_local = [to_local(ring) for ring in guidance.region]
        s.region = self._region_local
        s.region_of, s.go, s.value, s.note = guidance.region_of, guidance.go, guidance.value, guidance.note
        s.worst_case, s.uncertain = guidance.worst_case, guidance.uncertain
        s.boundary = [to_local(line) for line in guidance.boundary]
        for r in guidance.reports:
            old = s.reports.get(r.agent)
            if old is None or r.t >= old.t:
                where = self._place(r.agent, "fix", r.lon, r.lat)
                predicted = None if r.predicted is None else self._place(r.agent, "predicted", *r.predicted)
                ellipse = None if r.ellipse is None else (r.ellipse[0], r.ellipse[1], math.radians(r.ellipse[2]))
                s.reports[r.agent] = Sighting(where, r.t, r.radius, predicted, ellipse)

    def _place(self, agent: str, what: str, lon: float, lat: float) -> np.ndarray:
        """Where ``agent``'s ``what`` (its fix, or its tracker's prediction)
        at ``(lon, lat)`` is, in map metres. A report comes back in every
        guidance, ten times a second: its fix is the same until the next
        one, its prediction the same while the tracker expects no move. So
        each point is converted once per change, and the array is read-only,
        as the sightings share it."""
        held = self._places.get((agent, what))
        if held is None or held[0] != (lon, lat):
            place = np.array(self.map.to_local(lat, lon))
            place.flags.writeable = False
            held = self._places[(agent, what)] = ((lon, lat), place)
        return held[1]

    def _to_local(self, points) -> np.ndarray:
        """A ring or line of the wire's ``[lon, lat]`` points in map metres."""
        if not points:
            return np.zeros((0, 2))
        lon, lat = np.asarray(points, float).T
        return np.stack(self.map.to_local(lat, lon), axis=1)


def _unit(bearing: float) -> np.ndarray:
    """Unit (east, north) vector of a bearing in radians clockwise from north."""
    return np.array([math.sin(bearing), math.cos(bearing)])
