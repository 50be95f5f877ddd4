"""The guidance service: what each phone shows, from the fixes the network delivered.

Ten times a second (the scenario's rate) it takes the latest fix of every
agent, as the ground-station laptop of thesis 3.5 did, and sends each agent
a ``Guidance``: every agent as last reported, and for an aided agent the
solver's answer at those positions. Capture-the-flag guidance (3.5): the
attacker sees the defender's winning region R_D(x_a), its optimal heading
and go (the reported state is an attacker win); the defender sees R_A(x_d)
and its heading. An unaided agent's phone shows positions only.

Fixes are what the network delivered, GPS error included: a fix inside a
building or off the map is moved to the nearest free point before the
solver is asked, as a person's phone would still show them somewhere.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
import shapely.ops

from agents.protocol import Send
from bus import keys
from bus.messages import Fix, GameState, Guidance, Message, Report
from maps import Map
from solvers.ctf_guidance import Guidance as CtfGuidance
from solvers.errors import InputError

MAX_RING_POINTS = 4096


class _Fixes:
    """The latest fix per agent, in map metres, ignoring fixes older than the one held."""

    def __init__(self, game_map: Map) -> None:
        self.map = game_map
        self.latest: dict[str, tuple[np.ndarray, float, Fix]] = {}

    def take(self, fix: Fix) -> None:
        held = self.latest.get(fix.agent)
        if held is None or fix.t >= held[1]:
            self.latest[fix.agent] = (np.array(self.map.to_local(fix.lat, fix.lon)), fix.t, fix)

    def reports(self) -> list[Report]:
        return [Report(agent, f.t, f.lat, f.lon) for agent, (_, _, f) in self.latest.items()]


class CtfGuidanceService:
    """Guidance for a 1 vs 1 capture-the-flag game from its solved sets."""

    role = "ground-station"
    watches: tuple[str, ...] = ()

    def __init__(
        self,
        game: str,
        game_map: Map,
        solved: CtfGuidance,
        *,
        attacker: str,
        defender: str,
        aided: dict[str, bool],
        rate: float = 10.0,
        phase: str = "capture",
        name: str = "gs",
    ) -> None:
        self.game, self.name, self.map = game, name, game_map
        self.solved = solved
        self.attacker, self.defender = attacker, defender
        self.aided = aided
        self.period = 1.0 / rate
        self.phase = phase
        self.ended = False
        self.subscriptions = (keys.every(game, "fix"), keys.state(game))
        self.fixes = _Fixes(game_map)
        self.seq = 0
        spacing = min(solved.arena.grid.spacing)
        # Fixes outside the free space go to its nearest point a whisker inside.
        self._inside = game_map.free_space.buffer(-0.05 * spacing)
        self._simplify = 0.25 * spacing

    def start(self, now: float) -> list[Send]:
        return []

    def handle(self, key: str, message: Message, now: float) -> list[Send]:
        if isinstance(message, Fix):
            self.fixes.take(message)
        elif isinstance(message, GameState):
            self.ended = message.phase == "ended"
            self.phase = "capture" if message.flag_holder is None else "return"
        return []

    def peer(self, key: str, alive: bool, now: float) -> list[Send]:
        return []

    def tick(self, now: float) -> list[Send]:
        if self.ended:
            return []
        reports = self.fixes.reports()
        out = []
        for agent in (self.attacker, self.defender):
            fields = self._ctf(agent) if self.aided.get(agent) else {"game": "none"}
            self.seq += 1
            message = Guidance(agent=agent, seq=self.seq, t=now, reports=reports, **fields)
            out.append(Send(keys.guidance(self.game, agent), message))
        return out

    def _ctf(self, agent: str) -> dict:
        latest = self.fixes.latest
        if self.attacker not in latest or self.defender not in latest:
            return {"game": "ctf", "note": "waiting for both players' fixes"}
        try:
            a = self._placeable(latest[self.attacker][0])
            d = self._placeable(latest[self.defender][0])
            report = self.solved.evaluate(a, d, self.phase)
        except InputError as exc:
            return {"game": "ctf", "note": str(exc)[:200]}
        if agent == self.attacker:
            values, side, region_of, heading = (
                self.solved.defender_region_values(a, self.phase), "defender", self.defender, report.attacker_heading,
            )  # fmt: skip
        else:
            values, side, region_of, heading = (
                self.solved.attacker_region_values(d, self.phase), "attacker", self.attacker, report.defender_heading,
            )  # fmt: skip
        region = self._rings(self.solved.polygons(values, side))
        return {
            "game": "ctf",
            "heading": None if heading is None else _bearing(heading),
            "region": region,
            "region_of": region_of,
            "go": report.winner == "attacker" if agent == self.attacker else None,
            "value": float(report.value),
        }

    def _placeable(self, p: np.ndarray) -> np.ndarray:
        """``p``, or the nearest point of the free space if a fix put it in a building or off the map."""
        if self.solved.arena.grid.contains(p) and not self.solved.blocked_at(p):
            return p
        return np.asarray(shapely.ops.nearest_points(self._inside, shapely.Point(p))[0].coords[0])

    def _rings(self, region) -> list[list[tuple[float, float]]]:
        rings = []
        for polygon in shapely.get_parts(region)[:64]:
            ring = np.asarray(polygon.exterior.coords)
            if len(ring) > MAX_RING_POINTS:
                ring = np.asarray(polygon.exterior.simplify(self._simplify).coords)[:MAX_RING_POINTS]
            lat, lon = self.map.to_geodetic(ring[:, 0], ring[:, 1])
            rings.append(list(zip(np.atleast_1d(lat).tolist(), np.atleast_1d(lon).tolist())))
        return rings


def _bearing(vector) -> float:
    """Degrees clockwise from north of an (east, north) vector, in [0, 360)."""
    b = math.degrees(math.atan2(vector[0], vector[1])) % 360.0
    return 0.0 if b >= 360.0 else b
