"""UAV tasking: where the attacking side's UAVs search next (thesis 6.2).

Once a second the ground station updates P_D, where the defender may be,
from what the attacking side saw since (the attacker's line of sight V_A
from its last fix, every UAV's camera disk V_Q from its last fix, a
detection or a sighting collapsing it onto the defender), and sends each
UAV the next point its tasking policy (``tasking``: the reachability
hierarchy of eqs. 6.7-6.9, a lawnmower sweep, the nearest point where the
defender may be, or one's own) chooses. With several UAVs the points are
chosen in turn, each UAV treating the ground the ones before it are bound
for as about to be seen, so two UAVs do not search the same place. The
policy is called through a guard: when it fails, the UAV keeps its last
task for that second. While the defender is in sight the UAVs track it,
as in the 6.2.4 trials. Tasks go out every second even when they have not
changed: they are also each UAV's sign that the ground station is there
(its failsafe waits on them).

``picture`` keeps the latest sets, for the attacker's phone and the
recorder; everything is computed from fixes and detections, never truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
import shapely.ops

from bearcat.agents.ground_station.tasking import NEEDS_SETS, SearchView, TaskingPolicy, Uav, point_problem
from bearcat.agents.guard import Guard, PluginFault
from bearcat.agents.protocol import Send
from bearcat.agents.registry import Entry
from bearcat.bus import keys
from bearcat.bus.messages import Detection, Fix, GameState, Message, UavTask
from bearcat.maps import Map
from bearcat.maps.raster import rasterize
from bearcat.solvers import search
from bearcat.solvers.ctf.queries import CtfQueries
from bearcat.solvers.errors import InputError

PERIOD = 1.0  # s between updates and tasks
TRACK_FOR = 3.0  # s the UAV keeps tracking the defender's last sighting
PRIOR_RADIUS = 5.0  # m: P_D at the start, around the defender's known starting point


@dataclass
class Picture:
    """The search as the ground station last saw it (metres, grid masks)."""

    possible: np.ndarray | None = None
    targets: dict[str, tuple[float, float]] = field(default_factory=dict)
    tiers: dict[str, int | None] = field(default_factory=dict)
    strategy: str = ""
    updates: int = 0  # counts the updates, so a viewer redraws only what changed
    found_at: float | None = None  # first time the attacking side saw the defender
    sightings: list[tuple[float, str]] = field(default_factory=list)  # (time, by whom)


class UavTasker:
    role = "ground-station"
    watches: tuple[str, ...] = ()
    period = PERIOD

    def __init__(
        self,
        game: str,
        game_map: Map,
        *,
        uavs,
        attacker: str,
        defender: str,
        defender_start,
        defender_speed: float,
        policy: TaskingPolicy,
        entry: Entry,
        ctf: CtfQueries | None = None,
        sight,
        spacing: float = 2.0,
        name: str = "uav-tasking",
        guard: Guard | None = None,
    ) -> None:
        if entry.has(NEEDS_SETS) and ctf is None:
            raise InputError(f"UAV tasking by {entry.name} needs the capture-the-flag solution")
        self.game, self.name, self.map = game, name, game_map
        self.uavs = tuple(uavs)
        if not self.uavs:
            raise InputError("UAV tasking needs at least one UAV")
        self.attacker, self.defender = attacker, defender
        self.defender_speed = float(defender_speed)
        self.policy, self.strategy, self.ctf, self.sight = policy, entry.name, ctf, sight
        self.guard = guard or Guard(name, entry.name)
        self._check = point_problem(game_map)
        self.events: list[PluginFault] = []  # the guard's faults, which the runtime records
        self.subscriptions = (keys.every(game, "fix"), keys.every(game, "detection"), keys.state(game))
        raster = rasterize(game_map, spacing)
        self.grid, self.terrain = raster.grid, raster.speed
        self.free = self.terrain > 0
        self._nodes = np.stack(np.meshgrid(*self.grid.axes(), indexing="ij"), axis=-1)
        # Free space shrunk by a node, so a point moved into it lands on free nodes.
        self._inside = game_map.free_space.buffer(-max(self.grid.spacing))
        self.possible = search.PossibleDefender.around(self.terrain, self.grid, defender_start, PRIOR_RADIUS)
        self.picture = Picture(possible=self.possible.mask, strategy=entry.name)
        self.running = False
        self.ended = False
        self._fixes: dict[str, tuple[np.ndarray, float]] = {}
        self._seen: tuple[np.ndarray, float] | None = None  # the defender's last sighting by the attacking side
        self._last_update: float | None = None
        self._seq = 0
        self._phase = "return"

    # ------------------------------------------------------------------ agent protocol

    def start(self, now: float) -> list[Send]:
        return []

    def handle(self, key: str, message: Message, now: float) -> list[Send]:
        if isinstance(message, Fix):
            held = self._fixes.get(message.agent)
            if held is None or message.t > held[1]:
                self._fixes[message.agent] = (np.array(self.map.to_local(message.lat, message.lon)), message.t)
                self._check_sight(now)
        elif isinstance(message, Detection) and message.agent == self.defender:
            self._sighted(np.array(self.map.to_local(message.lat, message.lon)), message.t, message.uav)
        elif isinstance(message, GameState):
            self.running = message.phase == "running"
            self.ended = message.phase == "ended"
            self._phase = "capture" if message.flag_holder is None else "return"
        return []

    def peer(self, key: str, alive: bool, now: float) -> list[Send]:
        return []

    def tick(self, now: float) -> list[Send]:
        flying = [u for u in self.uavs if u.name in self._fixes]
        if self.ended or not self.running or self.attacker not in self._fixes or not flying:
            return []
        a = self._placeable(self._fixes[self.attacker][0])
        seen_a = search.visibility(self.free, self.grid, a)
        seen_q = np.zeros(self.grid.shape, dtype=bool)
        for u in flying:
            seen_q |= search.footprint(self.grid, self._fixes[u.name][0], u.camera_radius)
        dt = 0.0 if self._last_update is None else now - self._last_update
        self._last_update = now
        tracked = self._seen if self._seen is not None and now - self._seen[1] <= TRACK_FOR else None
        if tracked is not None:
            self.possible.found(tracked[0], radius=self.defender_speed * max(now - tracked[1], 0.0))
        else:
            self.possible.advance(dt, self.defender_speed, seen_a | seen_q)
        self.picture.possible = self.possible.mask
        claimed = np.zeros(self.grid.shape, dtype=bool)  # where the UAVs chosen before are bound
        out = []
        for u in flying:
            if tracked is not None:
                target, tier = tuple(tracked[0]), None
            else:
                target, tier = self._choose(now, u, a, seen_a, seen_q | claimed)
            self.picture.targets[u.name], self.picture.tiers[u.name] = target, tier
            if target is None:
                continue
            claimed |= search.footprint(self.grid, target, 2 * u.camera_radius)
            self._seq += 1
            lat, lon = self.map.to_geodetic(*target)
            task = UavTask(uav=u.name, seq=self._seq, t=now, kind="search", lat=lat, lon=lon, alt=u.altitude)
            out.append(Send(keys.uav_task(self.game, u.name), task))
        self.picture.updates += 1
        self.events += self.guard.faults[len(self.events) :]
        return out

    # ------------------------------------------------------------------ sensing

    def _check_sight(self, now: float) -> None:
        """A sighting when the defender's and the attacker's fixes see each other."""
        a, d = self._fixes.get(self.attacker), self._fixes.get(self.defender)
        if a is not None and d is not None and self.sight.sees(a[0], d[0]):
            self._sighted(d[0], d[1], self.attacker)

    def _sighted(self, where: np.ndarray, t: float, by: str) -> None:
        if self._seen is None or t > self._seen[1]:
            self._seen = (self._placeable(where), t)
            if self.picture.found_at is None:
                self.picture.found_at = t
            self.picture.sightings.append((t, by))

    def _placeable(self, p: np.ndarray) -> np.ndarray:
        """``p``, or the nearest free point if GPS error put the fix in a
        building or off the map (a phone still shows its owner somewhere)."""
        p = np.clip(p, self.grid.lo, self.grid.hi)
        if self.free[self.grid.nearest_index(p)]:
            return p
        return np.asarray(shapely.ops.nearest_points(self._inside, shapely.Point(p))[0].coords[0])

    # ------------------------------------------------------------------ where next

    def _choose(self, now: float, u: Uav, a, seen_a, seen_q):
        """UAV ``u``'s next point and its tier, by the policy; its last one
        if the policy failed. ``seen_q`` holds what the cameras see and
        where the UAVs tasked before it are bound."""
        view = SearchView(
            map=self.map,
            grid=self.grid,
            terrain=self.terrain,
            possible=self.possible.mask & ~seen_q,
            seen_by_attacker=seen_a,
            seen_by_uavs=seen_q,
            attacker=a,
            at=self._fixes[u.name][0],
            defender_speed=self.defender_speed,
            defender_wins=lambda: self._defender_wins(a),
            uavs=self.uavs,
        )
        last = (self.picture.targets.get(u.name), self.picture.tiers.get(u.name))
        answer = self.guard.call(now, self.policy.next_point, u, view, check=self._check, fallback=last)
        if answer is None:
            return None, None
        target, tier = answer
        return (None if target is None else (float(target[0]), float(target[1]))), tier

    def worst_case(self, attacker, values=None) -> tuple[float, float] | None:
        """The place in P_D where the defender would do best against an
        attacker at ``attacker``, or given the defender's ``values`` on the
        solver's grid (the worst over where the attacker may be); None if
        P_D is empty or there is no solution."""
        possible = self.picture.possible
        if values is None:
            values = self._defender_values(self._placeable(np.asarray(attacker, float)))
        else:
            values = self._resampled(values)
        if possible is None or values is None or not possible.any():
            return None
        masked = np.where(possible, values, -np.inf)
        k = np.unravel_index(int(np.argmax(masked)), masked.shape)
        x, y = self.grid.point(k)
        return float(x), float(y)

    def adopt(self, ctf: CtfQueries) -> None:
        """Search from ``ctf`` from now on: the game's own sets, taken up after provisional ones."""
        self.ctf = ctf

    def _defender_wins(self, attacker) -> np.ndarray:
        """W_D(x_a) on the search grid."""
        values = self._defender_values(attacker)
        return np.zeros(self.grid.shape, dtype=bool) if values is None else (values > 0) & self.free

    def _defender_values(self, attacker) -> np.ndarray | None:
        """The solved game's value over defender positions with the attacker at
        ``attacker`` (> 0: the defender wins), resampled onto the search grid."""
        if self.ctf is None:
            return None
        try:
            values = self.ctf.defender_region_values(attacker, self._phase)
        except InputError:  # the attacker's fix is off the solver's grid or in a building
            return None
        return self._resampled(values)

    def _resampled(self, values: np.ndarray) -> np.ndarray:
        """A field on the solver's player grid, on the search grid."""
        from scipy.interpolate import RegularGridInterpolator  # half a second to import, for UAV games only

        assert self.ctf is not None  # the field came from its sets
        sample = RegularGridInterpolator(self.ctf.geometry.grid.axes(), values, bounds_error=False, fill_value=-1.0)
        return sample(self._nodes)
