"""The comparison trials of thesis 5.3.2: safe-reachable-area pursuit against
pure pursuit, from the same random initial conditions, against the
farthest-point evader, for 1, 2 and 3 pursuers in a convex, a simple
non-convex and a complex non-convex domain (Table 5.1, Fig. 5.11).

The setup, which the thesis leaves partly open, is fixed here and recorded
with every run: all speeds 1, capture radius 0.5, time step 0.1 (two agents
closing head-on cover 0.2 per step, well inside the capture radius, and
capture is checked over each step in any case), a limit of 100 s per chase,
positions drawn uniformly over the free space with every pursuer at least
1.0 from the evader. Convex domains use the analytic strategy of 5.2.1 and
straight-line pure pursuit; the others the fast-marching strategy of 5.2.2
on a 0.1 m grid and pure pursuit along geodesics. A trial counts for area
pursuit when it captures strictly sooner; a chase that times out counts as
infinitely long.

Each trial is one task with its own seed (a ``numpy.random.SeedSequence``
spawned from the run's seed, the domain, the pursuer count and the trial
number), so any trial can be rerun alone and gives the same result on any
worker and in any run that includes it.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import asdict, dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from bearcat.maps import load_map, rasterize
from bearcat.solvers.pursuit.game import pursue

if TYPE_CHECKING:
    from bearcat.solvers.pursuit.fmm import TravelTimes

THESIS_TABLE = {
    "square-10": (91.6, 98.2, 96.6),
    "triangle-10": (67.2, 86.2, 86.4),
    "maze-10": (48.2, 72.6, 76.4),
    "maze-deadend-10": (48.2, 72.6, 76.4),  # the same row: another reading of Fig. 5.9c
}
"""Table 5.1: % of trials where area pursuit captured faster, for 1 / 2 / 3 pursuers."""


@dataclass(frozen=True)
class PursuitSetup:
    capture_radius: float = 0.5
    speed: float = 1.0
    dt: float = 0.1
    max_time: float = 100.0
    spacing: float = 0.1
    separation: float = 1.0
    gradient: str = "boundary"


def trial_tasks(domains, pursuer_counts, trials: int, seed: int, setup: PursuitSetup) -> list[dict]:
    """One task per (domain, pursuer count, trial number), in that order."""
    tasks = []
    for domain in domains:
        # The domain enters the seed by name, not by its place in the list,
        # so a trial is the same whichever other domains a run includes.
        d = zlib.crc32(domain.encode())
        for n in pursuer_counts:
            for index in range(trials):
                tasks.append(
                    {
                        "key": f"{domain}/{n}/{index}",
                        "domain": domain,
                        "pursuers": int(n),
                        "index": index,
                        "seed": [int(seed), d, int(n), index],
                        "setup": asdict(setup),
                    }
                )
    return tasks


def run_trial(task: dict) -> dict:
    """Both strategies from one initial condition; a JSON-ready result."""
    setup = PursuitSetup(**task["setup"])
    domain = _domain(task["domain"], setup.spacing, setup.capture_radius, setup.speed, setup.gradient)
    entropy, *spawn = task["seed"]
    rng = np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=tuple(spawn)))
    evader, pursuers = domain.initial_condition(rng, task["pursuers"], setup.separation)
    times: dict[str, float | None] = {}
    for name in ("area", "pure"):
        # One set of travel times per chase, shared by the evader and the pursuers,
        # so the fronts and the safe set one computes for a state serve the other.
        travel_times = domain.travel_times()
        chase = pursue(
            domain.strategy(name, travel_times),
            domain.evader(travel_times),
            evader,
            pursuers,
            passable=domain.passable,
            dt=setup.dt,
            capture_radius=setup.capture_radius,
            evader_speed=setup.speed,
            pursuer_speeds=setup.speed,
            max_time=setup.max_time,
        )
        times[name] = chase.capture_time
    area, pure = (math.inf if t is None else t for t in (times["area"], times["pure"]))
    return {
        "key": task["key"],
        "domain": task["domain"],
        "kind": domain.kind,
        "pursuers": task["pursuers"],
        "index": task["index"],
        "seed": task["seed"],
        "evader": [round(float(v), 4) for v in evader],
        "pursuer_positions": [[round(float(v), 4) for v in p] for p in pursuers],
        "area_time": times["area"],
        "pure_time": times["pure"],
        "area_faster": bool(area < pure),
    }


def summarise(results, domains, pursuer_counts) -> dict:
    """Per domain and pursuer count: trials, the share where area pursuit was
    faster (%), capture-time quantiles of both strategies and the
    differences ``area - pure`` for the histograms (finite ones only)."""
    table = {}
    for domain in domains:
        for n in pursuer_counts:
            rows = [r for r in results if r["domain"] == domain and r["pursuers"] == n]
            if not rows:
                continue
            area = np.array([np.inf if r["area_time"] is None else r["area_time"] for r in rows])
            pure = np.array([np.inf if r["pure_time"] is None else r["pure_time"] for r in rows])
            finite = np.isfinite(area) & np.isfinite(pure)
            thesis = THESIS_TABLE.get(domain)
            table[f"{domain}/{n}"] = {
                "domain": domain,
                "pursuers": n,
                "trials": len(rows),
                "area_faster_percent": round(100.0 * float(np.mean(area < pure)), 1),
                "thesis_percent": thesis[n - 1] if thesis and 1 <= n <= 3 else None,
                "area_uncaptured": int(np.sum(~np.isfinite(area))),
                "pure_uncaptured": int(np.sum(~np.isfinite(pure))),
                "area_time_quartiles": _quartiles(area),
                "pure_time_quartiles": _quartiles(pure),
                "differences": [round(float(v), 3) for v in area[finite] - pure[finite]],
            }
    return table


def _quartiles(times: np.ndarray) -> list[float | None]:
    finite = times[np.isfinite(times)]
    if finite.size == 0:
        return [None, None, None]
    return [round(float(v), 2) for v in np.percentile(finite, [25, 50, 75])]


class _Domain:
    """A map as the trials use it: its strategies, its evader, a free-space
    test and a sampler of initial conditions."""

    def __init__(self, name: str, spacing: float, capture_radius: float, speed: float, gradient: str) -> None:
        game_map = load_map(name)
        free = game_map.free_space
        self.kind = "convex" if math.isclose(free.area, free.convex_hull.area, rel_tol=1e-9) else "non-convex"
        self.bounds = np.array(game_map.bounds)
        self.capture_radius, self.speed, self.gradient = capture_radius, speed, gradient
        raster = rasterize(game_map, spacing)
        self.grid, self.free = raster.grid, raster.free
        self.raster_speed = raster.speed
        if self.kind == "convex":
            ring = np.asarray(free.exterior.coords)[:-1]
            if not free.exterior.is_ccw:
                ring = ring[::-1]
            self.polygon = np.ascontiguousarray(ring, dtype=float)
            # Outward normals and offsets of the convex polygon's edges.
            edges = np.roll(self.polygon, -1, axis=0) - self.polygon
            self.normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
            self.offsets = np.einsum("ij,ij->i", self.normals, self.polygon)

    def passable(self, point) -> bool:
        x, y = float(point[0]), float(point[1])
        if self.kind == "convex":
            return bool(np.all(self.normals @ (x, y) <= self.offsets + 1e-9))
        xmin, ymin, xmax, ymax = self.bounds
        if not (xmin <= x <= xmax and ymin <= y <= ymax):
            return False
        i, j = self.grid.nearest_index((x, y))
        return bool(self.free[i, j])

    def initial_condition(self, rng, pursuers: int, separation: float):
        def sample():
            while True:
                p = rng.uniform(self.bounds[:2], self.bounds[2:])
                if self.passable(p):
                    return p

        evader = sample()
        chosen: list[np.ndarray] = []
        while len(chosen) < pursuers:
            p = sample()
            if np.hypot(*(p - evader)) > separation:
                chosen.append(p)
        return evader, np.array(chosen)

    def strategy(self, name: str, travel_times):
        if self.kind == "convex":
            from bearcat.solvers.pursuit.convex import ConvexAreaPursuit, StraightPursuit

            return ConvexAreaPursuit(self.polygon) if name == "area" else StraightPursuit()
        from bearcat.solvers.pursuit.fmm import FmmAreaPursuit, GeodesicPursuit

        if name == "area":
            return FmmAreaPursuit(
                travel_times,
                evader_speed=self.speed,
                pursuer_speeds=self.speed,
                capture_radius=self.capture_radius,
                gradient=self.gradient,
            )
        return GeodesicPursuit(travel_times)

    def evader(self, travel_times):
        if self.kind == "convex":
            from bearcat.solvers.pursuit.convex import ConvexFarthestPointEvader

            return ConvexFarthestPointEvader(self.polygon, self.capture_radius)
        from bearcat.solvers.pursuit.fmm import FarthestPointEvader

        return FarthestPointEvader(
            travel_times, evader_speed=self.speed, pursuer_speeds=self.speed, capture_radius=self.capture_radius
        )

    def travel_times(self) -> TravelTimes | None:
        """Travel times over a non-convex domain (None for a convex one, whose strategies are analytic)."""
        if self.kind == "convex":
            return None
        from bearcat.solvers.pursuit.fmm import TravelTimes

        return TravelTimes(self.grid, self.raster_speed)


@lru_cache(maxsize=8)
def _domain(name: str, spacing: float, capture_radius: float, speed: float, gradient: str) -> _Domain:
    """Built once per worker process and reused by its trials."""
    return _Domain(name, spacing, capture_radius, speed, gradient)
