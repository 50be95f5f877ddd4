"""The guidance service: what each phone shows, from the fixes the network delivered.

For each agent, on each of its new fixes and at least ten times a second
(the scenario's rate), it takes the latest fix of every agent, as the
ground-station laptop of thesis 3.5 did, and sends that agent a
``Guidance``: every agent as last reported, and for an aided agent the
solver's answer at those positions. Capture-the-flag guidance (3.5): the
attacker sees the defender's winning region R_D(x_a), its optimal heading
and go (the reported state is an attacker win); the defender sees R_A(x_d)
and its heading. An unaided agent's phone shows positions only.

In a game of limited visibility (a ``Sight``), each agent is told only
what its side has seen: its teammates and their UAVs always, an opponent
while the two are in line of sight (both learn of each other at once) or
when one of its side's UAVs detected it; the agent a UAV saw is alerted
(``seen_by``). The solver then answers from what that agent knows.

Fixes are what the network delivered, GPS error included: a fix inside a
building or off the map is moved to the nearest free point before the
solver is asked, as a person's phone would still show them somewhere.
"""

from __future__ import annotations

import numpy as np
import shapely
import shapely.ops

from bearcat.agents.protocol import Send
from bearcat.bus import keys
from bearcat.bus.messages import Detection, Fix, GameState, Guidance, Message, Report
from bearcat.maps import Map
from bearcat.maps.geodesy import bearing
from bearcat.solvers.ctf_guidance import Guidance as CtfGuidance
from bearcat.solvers.errors import InputError

MAX_RING_POINTS = 4096
SPOTTED_FOR = 2.0  # s an agent's screen says a UAV saw it


class _Fixes:
    """The latest fix per agent, in map metres, ignoring fixes older than the one held."""

    def __init__(self, game_map: Map) -> None:
        self.map = game_map
        self.latest: dict[str, tuple[np.ndarray, float, Fix]] = {}

    def take(self, fix: Fix) -> bool:
        """Keep ``fix`` if it is newer than the one held; whether it was."""
        held = self.latest.get(fix.agent)
        if held is None or fix.t > held[1]:
            self.latest[fix.agent] = (np.array(self.map.to_local(fix.lat, fix.lon)), fix.t, fix)
            return True
        return False

    def reports(self) -> list[Report]:
        return [Report(agent, f.t, f.lat, f.lon) for agent, (_, _, f) in self.latest.items()]


class GuidanceService:
    """Sends each of ``agents`` its guidance: as soon as a new fix of that
    agent arrives (so a phone's answer follows its own fix at once, and no
    faster than its fixes come), and at the scenario's ``rate`` whenever a
    period passed without one (so it also follows the others' moves).
    ``advisor(agent, fixes, now)`` adds the solver's part for an aided agent
    (None: positions only)."""

    role = "ground-station"
    watches: tuple[str, ...] = ()

    def __init__(
        self,
        game: str,
        game_map: Map,
        agents,
        *,
        advisor=None,
        aided=None,
        rate: float = 10.0,
        name: str = "gs",
        sight=None,
    ) -> None:
        self.game, self.name, self.map = game, name, game_map
        self.agents = tuple(agents)
        self.advisor = advisor
        self.aided = dict(aided or {})
        self.period = 1.0 / rate
        self.ended = False
        self.sight = sight
        self.subscriptions = (keys.every(game, "fix"), keys.state(game))
        if sight is not None:
            self.subscriptions += (keys.every(game, "detection"),)
        self.fixes = _Fixes(game_map)
        self.known = {a: _Fixes(game_map) for a in self.agents} if sight is not None else None
        self.spotted: dict[str, tuple[str, float]] = {}  # agent -> (UAV that saw it, when)
        self.seq = 0
        self._last = {a: -np.inf for a in self.agents}

    def start(self, now: float) -> list[Send]:
        return []

    def handle(self, key: str, message: Message, now: float) -> list[Send]:
        if isinstance(message, Fix):
            if not self.fixes.take(message):
                return []
            if self.known is not None:
                self._share(message)
            if message.agent in self._last:
                return self._send([message.agent], now)
        elif isinstance(message, Detection) and self.known is not None:
            seen = Fix(agent=message.agent, seq=0, t=message.t, lat=message.lat, lon=message.lon)
            for viewer in self.agents:
                if self.sight.allies(viewer, message.uav):
                    self.known[viewer].take(seen)
            self.spotted[message.agent] = (message.uav, now)
        elif isinstance(message, GameState):
            self.ended = message.phase == "ended"
            if self.advisor is not None:
                self.advisor.state(message)
        return []

    def peer(self, key: str, alive: bool, now: float) -> list[Send]:
        return []

    def tick(self, now: float) -> list[Send]:
        due = [a for a in self.agents if now - self._last[a] >= self.period - 1e-9]
        return self._send(due, now)

    def _share(self, fix: Fix) -> None:
        """Tell whoever may know of ``fix``: its side; and, if it is in line of
        sight of an opponent, that opponent, who is seen in turn."""
        sight, mover = self.sight, fix.agent
        where = self.fixes.latest[mover][0]
        for viewer in self.agents:
            if sight.allies(viewer, mover):
                self.known[viewer].take(fix)
                continue
            held = self.fixes.latest.get(viewer)
            if held is None or mover in sight.uavs or not sight.sees(held[0], where):
                continue
            self.known[viewer].take(fix)
            if mover in self.known:
                self.known[mover].take(held[2])

    def _send(self, agents, now: float) -> list[Send]:
        if self.ended or not agents:
            return []
        everything = self.fixes.reports() if self.known is None else None
        out = []
        for agent in agents:
            fixes = self.fixes if self.known is None else self.known[agent]
            fields = {"game": "none"}
            if self.advisor is not None and self.aided.get(agent):
                fields = self.advisor(agent, fixes, now)
            spotted = self.spotted.get(agent)
            if spotted is not None and now - spotted[1] <= SPOTTED_FOR:
                fields = {**fields, "seen_by": [spotted[0]]}
            self.seq += 1
            self._last[agent] = now
            reports = everything if everything is not None else fixes.reports()
            out.append(
                Send(
                    keys.guidance(self.game, agent),
                    Guidance(agent=agent, seq=self.seq, t=now, reports=reports, **fields),
                )
            )
        return out


class CtfAdvisor:
    """Capture-the-flag guidance from the solved sets (thesis 3.5): the
    attacker's phone shows R_D(x_a), its heading and go; the defender's
    R_A(x_d) and its heading."""

    def __init__(self, game_map: Map, solved: CtfGuidance, *, attacker: str, defender: str, phase: str = "capture"):
        self.map = game_map
        self.solved = solved
        self.attacker, self.defender = attacker, defender
        self.phase = phase
        spacing = min(solved.arena.grid.spacing)
        # Fixes outside the free space go to its nearest point a whisker inside.
        self._inside = game_map.free_space.buffer(-0.05 * spacing)
        self._simplify = 0.25 * spacing
        self._last: dict[str, tuple[tuple, dict]] = {}

    def state(self, message: GameState) -> None:
        self.phase = "capture" if message.flag_holder is None else "return"

    def __call__(self, agent: str, fixes: _Fixes, now: float) -> dict:
        """The CTF fields of ``agent``'s guidance. They depend only on the two
        latest fixes and the phase, which change about once a second while
        guidance goes out ten times, so the last answer per agent is kept."""
        latest = fixes.latest
        if self.attacker not in latest or self.defender not in latest:
            return {"game": "ctf", "note": "waiting for both players' fixes"}
        a, d = latest[self.attacker][0], latest[self.defender][0]
        key = (a[0], a[1], d[0], d[1], self.phase)
        held = self._last.get(agent)
        if held is None or held[0] != key:
            held = self._last[agent] = (key, self.answer_at(agent, a, d))
        return held[1]

    def answer_at(self, agent: str, a: np.ndarray, d: np.ndarray) -> dict:
        """The CTF fields of ``agent``'s guidance with the attacker at ``a`` and
        the defender at ``d`` (map metres; moved out of buildings first)."""
        try:
            a = self._placeable(a)
            d = self._placeable(d)
            report = self.solved.evaluate(a, d, self.phase)
        except InputError as exc:
            return {"game": "ctf", "note": str(exc)[:200]}
        if agent == self.attacker:
            values, side, region_of, heading = (
                self.solved.defender_region_values(a, self.phase),
                "defender",
                self.defender,
                report.attacker_heading,
            )
        else:
            values, side, region_of, heading = (
                self.solved.attacker_region_values(d, self.phase),
                "attacker",
                self.attacker,
                report.defender_heading,
            )
        return {
            "game": "ctf",
            "heading": None if heading is None else bearing(*heading),
            "region": self._rings(self.solved.polygons(values, side)),
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


class PursuitAdvisor:
    """Cooperative pursuit guidance in a convex field (thesis 5.4): each
    pursuer's phone shows the evader's safe-reachable set S_e (its Voronoi
    cell), the pursuer's own active boundary of it, and the heading that
    shrinks its area fastest (eq. 5.11; straight at the evader for a pursuer
    without a boundary); ``value`` is the area of S_e in square metres."""

    def __init__(self, game_map: Map, *, evader: str, pursuers) -> None:
        from bearcat.solvers.pursuit import area_minimising_headings, voronoi_cell

        self.map = game_map
        self.evader, self.pursuers = evader, tuple(pursuers)
        ring = np.asarray(game_map.area.exterior.coords)[:-1]
        self.domain = ring if game_map.area.exterior.is_ccw else ring[::-1]
        self._headings, self._cell = area_minimising_headings, voronoi_cell
        self._last: dict[str, tuple[tuple, dict]] = {}

    def state(self, message: GameState) -> None:
        pass

    def __call__(self, agent: str, fixes: _Fixes, now: float) -> dict:
        latest = fixes.latest
        if agent not in self.pursuers or any(a not in latest for a in (self.evader, *self.pursuers)):
            return {"game": "pursuit", "note": "waiting for every player's fixes"}
        e = latest[self.evader][0]
        ps = np.array([latest[p][0] for p in self.pursuers])
        key = (tuple(e), ps.tobytes())
        held = self._last.get(agent)
        if held is None or held[0] != key:
            held = self._last[agent] = (key, self._answer(agent, e, ps))
        return held[1]

    def _answer(self, agent: str, e: np.ndarray, ps: np.ndarray) -> dict:
        k = self.pursuers.index(agent)
        try:
            heading = self._headings(self.domain, e, ps)[k]
            cell = self._cell(self.domain, e, ps)
        except InputError as exc:
            return {"game": "pursuit", "note": str(exc)[:200]}
        # Pursuer k's active boundary: the cell's corners as far from it as from the evader.
        on_line = [
            v for v in cell if abs(np.hypot(*(v - ps[k])) - np.hypot(*(v - e))) < 1e-6 * max(1.0, np.hypot(*(v - e)))
        ]
        fields = {"game": "pursuit", "region_of": self.evader, "value": float(_shoelace(cell)) if len(cell) else 0.0}
        if np.any(heading):
            fields["heading"] = bearing(*heading)
        if len(cell) >= 3:
            fields["region"] = [self._geodetic(np.vstack([cell, cell[:1]]))]
        if len(on_line) >= 2:
            fields["boundary"] = [self._geodetic(np.array(on_line[:2]))]
        return fields

    def _geodetic(self, points: np.ndarray) -> list[tuple[float, float]]:
        lat, lon = self.map.to_geodetic(points[:, 0], points[:, 1])
        return list(zip(np.atleast_1d(lat).tolist(), np.atleast_1d(lon).tolist()))


class ReachAvoidAdvisor:
    """Open-loop reach-avoid guidance (thesis ch. 4) for one attacker against
    many defenders: the attacker's phone shows its safe-reachable set for the
    current stage, the planned path through the remaining targets as a line,
    its first stretch as the heading, and go when a safe path exists;
    ``value`` is the time to the last target along it. Solved on a grid of
    ``spacing`` metres on each new fix of the attacker."""

    def __init__(
        self, game_map: Map, *, attacker: str, defenders, targets, speeds: dict, capture_radius: float, spacing: float
    ) -> None:
        from bearcat.maps import rasterize

        self.map = game_map
        self.attacker, self.defenders = attacker, tuple(defenders)
        raster = rasterize(game_map, spacing)
        self.grid = raster.grid
        self.free = raster.free
        # Fixes that land on a blocked node go to the nearest point a spacing inside the free space.
        self._inside = game_map.free_space.buffer(-spacing)
        self.masks = [raster.masks[name] for name in targets]
        self.speed = {agent: v * raster.speed for agent, v in speeds.items()}
        self.capture_radius = capture_radius
        self.stage = 0
        self._last: tuple[tuple, dict] | None = None

    def state(self, message: GameState) -> None:
        self.stage = 0 if message.flag_holder is None else min(1, len(self.masks) - 1)

    def __call__(self, agent: str, fixes: _Fixes, now: float) -> dict:
        latest = fixes.latest
        if agent != self.attacker:
            return {"game": "reach-avoid"}
        if any(a not in latest for a in (self.attacker, *self.defenders)):
            return {"game": "reach-avoid", "note": "waiting for every player's fixes"}
        points = [latest[a][0] for a in (self.attacker, *self.defenders)]
        # A solve takes tens of milliseconds: redo it when the stage changes or
        # the attacker's own fix moves (once a fix period), taking the
        # defenders as last reported then; a defender's move shows at the
        # attacker's next fix.
        key = (self.stage, points[0].tobytes())
        if self._last is None or self._last[0] != key:
            self._last = (key, self._answer(points))
        return self._last[1]

    def _answer(self, points) -> dict:
        from bearcat.solvers.openloop import Defender, solve_openloop

        a, *others = (self._placeable(p) for p in points)
        defenders = [Defender(tuple(p), self.speed[d], self.capture_radius) for d, p in zip(self.defenders, others)]
        masks = self.masks[self.stage :]
        try:
            solution = solve_openloop(self.grid, tuple(a), [self.speed[self.attacker]] * len(masks), masks, defenders)
        except InputError as exc:
            return {"game": "reach-avoid", "note": str(exc)[:200]}
        fields = {"game": "reach-avoid", "region_of": self.attacker, "go": solution.reached}
        fields["region"] = _geodetic_rings(self.map, _mask_rings(self.grid, solution.stages[0].safe))
        if solution.path is not None and len(solution.path.points) > 1:
            path = solution.path.points
            along = np.cumsum(np.r_[0.0, np.hypot(*np.diff(path, axis=0).T)])
            aim = path[min(int(np.searchsorted(along, 3.0 * max(self.grid.spacing))), len(path) - 1)]
            if np.hypot(*(aim - a)) > 1e-9:
                fields["heading"] = bearing(*(aim - a))
            fields["boundary"] = _geodetic_rings(self.map, [path[:: max(1, len(path) // 2000)]])
            fields["value"] = float(solution.value)
        return fields

    def _placeable(self, p: np.ndarray) -> np.ndarray:
        p = np.clip(p, self.grid.lo, self.grid.hi)
        if self.free[self.grid.nearest_index(p)]:
            return p
        return np.asarray(shapely.ops.nearest_points(self._inside, shapely.Point(p))[0].coords[0])


class SearchAdvisor:
    """Capture-the-flag guidance under limited visibility (thesis 6.2): the
    CTF answer from what the agent's side knows; and for the side that flies
    the UAV, where the unseen defender may be (P_D, from its tasker) and the
    answer against the worst of those places: the value is the largest over
    P_D, so "go" means the attacker wins wherever the defender is, seen or
    not (``worst_case``). P_D grows with the time since the defender was
    last seen, so a stale sighting counts for what it is worth."""

    def __init__(self, ctf: CtfAdvisor, tasker, side) -> None:
        self.ctf = ctf
        self.tasker = tasker
        self.side = frozenset(side)
        self._drawn: tuple[int, list] = (-1, [])
        self._worst: tuple[tuple, dict | None] = ((), None)

    def state(self, message: GameState) -> None:
        self.ctf.state(message)

    def __call__(self, agent: str, fixes: _Fixes, now: float) -> dict:
        fields = {**self.ctf(agent, fixes, now), "game": "search"}
        if agent in self.side:
            fields["possible"] = self._possible()
            if self.ctf.attacker in fixes.latest:
                fields.update(self._against_the_worst(agent, fixes.latest[self.ctf.attacker][0]))
        return fields

    def _against_the_worst(self, agent: str, a: np.ndarray) -> dict:
        key = (agent, a[0], a[1], self.tasker.picture.updates, self.ctf.phase)
        if self._worst[0] != key:
            worst = self.tasker.worst_case(a)
            answer = None
            if worst is not None:
                answer = self.ctf.answer_at(agent, a, np.asarray(worst))
                answer = {k: answer[k] for k in ("heading", "value", "go") if k in answer}
                answer["worst_case"] = "value" in answer
            self._worst = (key, answer)
        return self._worst[1] or {}

    def _possible(self) -> list:
        """P_D's outlines, redrawn only when the tasker updated it (once a second)."""
        picture = self.tasker.picture
        if picture.updates != self._drawn[0]:
            self._drawn = (
                picture.updates,
                _geodetic_rings(self.ctf.map, _mask_rings(self.tasker.grid, picture.possible)),
            )
        return self._drawn[1]


def _geodetic_rings(game_map: Map, rings) -> list:
    out = []
    for ring in rings[:64]:
        ring = np.asarray(ring)[:MAX_RING_POINTS]
        lat, lon = game_map.to_geodetic(ring[:, 0], ring[:, 1])
        out.append(list(zip(np.atleast_1d(lat).tolist(), np.atleast_1d(lon).tolist())))
    return out


def _mask_rings(grid, mask: np.ndarray) -> list[np.ndarray]:
    """The outlines of a set of grid nodes, traced halfway to the nodes outside."""
    import contourpy

    if not mask.any():
        return []
    x, y = grid.axes()
    lines = contourpy.contour_generator(x, y, mask.T.astype(float), line_type="Separate").lines(0.5)
    return sorted((line for line in lines if len(line) >= 4), key=len, reverse=True)


def _shoelace(ring: np.ndarray) -> float:
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
