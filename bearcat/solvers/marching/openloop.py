"""The open-loop reach-avoid game of one attacker against many defenders (thesis 4.1-4.2).

The attacker commits to a path first; every defender then knows it. A point is
safe-reachable when the attacker gets there before any defender could come
within its capture radius, along a path of such points. The modified fast
marching method computes that set ``S`` and the attacker's arrival times
``phi`` together, stage after stage for a sequence of targets, and the
optimal path is read back from the last target through every stage.

All times are seconds since the start of the game: the defenders keep
closing in during every stage, so one time-to-capture map serves all stages.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from bearcat.solvers.errors import InputError, non_negative
from bearcat.solvers.grid import Grid
from bearcat.solvers.marching import fmm
from bearcat.solvers.marching.descent import descend

__all__ = ["Defender", "OpenLoopPath", "OpenLoopSolution", "StageSolution", "solve_openloop"]


@dataclass(frozen=True)
class Defender:
    """A defender's start, its top speed per node (0: impassable) and capture radius."""

    position: tuple[float, float]
    speed: np.ndarray
    capture_radius: float = 0.0


@dataclass(frozen=True)
class StageSolution:
    """One stage: arrival times ``phi`` (infinite outside ``safe``, the set S_k),
    the stage value (earliest safe arrival in the target, infinite if none),
    the area of S_k and ``goal``, the target point reached at that time."""

    phi: np.ndarray
    safe: np.ndarray
    value: float
    safe_area: float
    goal: tuple[float, float] | None


@dataclass(frozen=True)
class OpenLoopPath:
    """The attacker's path through all stages: ``points`` (n, 2) in metres,
    ``times`` (n,) seconds since the start, increasing, and ``stage_starts``,
    the index of the vertex where each stage begins."""

    points: np.ndarray
    times: np.ndarray
    stage_starts: tuple[int, ...]


@dataclass(frozen=True)
class OpenLoopSolution:
    """``capture_time`` is psi^c, the earliest time any defender can capture
    at each node. ``stages`` has one entry per target; after a blocked stage
    the rest are empty. ``path`` is None and ``blocked_stage`` the index of
    the first target with no safe-reachable node when there is no safe path."""

    grid: Grid
    capture_time: np.ndarray
    stages: tuple[StageSolution, ...]
    path: OpenLoopPath | None
    blocked_stage: int | None

    @property
    def reached(self) -> bool:
        return self.blocked_stage is None

    @property
    def value(self) -> float:
        """Time at which the attacker safely reaches the last target (inf if it cannot)."""
        return self.stages[-1].value


def solve_openloop(
    grid: Grid,
    attacker: tuple[float, float],
    stage_speeds: Sequence[np.ndarray],
    targets: Sequence[np.ndarray],
    defenders: Sequence[Defender],
    *,
    order: int = 1,
) -> OpenLoopSolution:
    """Solve the multi-stage open-loop game for the attacker.

    ``stage_speeds[k]`` is the attacker's top speed per node during stage
    ``k``, which ends on reaching the boolean mask ``targets[k]``. Defenders,
    stages and targets are counted from 1 in error messages.
    """
    if grid.ndim != 2:
        raise InputError(f"the open-loop game is played on a 2-D grid, got {grid.ndim} dimensions")
    source = _check_point(grid, attacker, "attacker")
    stage_speeds = [_check_speed(grid, s, f"stage {k + 1} speed") for k, s in enumerate(stage_speeds)]
    targets = [_check_target(grid, t, k) for k, t in enumerate(targets)]
    if not targets:
        raise InputError("the game needs at least one target")
    if len(stage_speeds) != len(targets):
        raise InputError(f"got {len(stage_speeds)} stage speed maps for {len(targets)} targets")
    if order not in (1, 2):
        raise InputError(f"order must be 1 or 2, got {order!r}")
    _check_passable(grid, source, stage_speeds[0], "attacker")
    hx, hy = grid.spacing

    checked = [_check_defender(grid, d, k) for k, d in enumerate(defenders)]
    capture_time = _capture_time(grid, checked, order)

    stages: list[StageSolution] = []
    seeds: list[np.ndarray] = []
    initial = fmm.point_source(grid, source, stage_speeds[0])
    # Within a capture radius at t = 0 is captured, even where the grid nodes
    # around (all the marching sees) are not.
    if any(math.dist(source, position) <= radius for position, _, radius in checked):
        initial[:] = np.inf
    blocked = None
    for k, (speed, target) in enumerate(zip(stage_speeds, targets)):
        if blocked is not None:
            stages.append(_empty_stage(grid))
            continue
        phi = fmm.march(speed, hx, hy, initial, capture_time, order)
        stage = _stage(grid, phi, target)
        stages.append(stage)
        # A seed the front improved on is not where the stage begins; the
        # descent must stop only where phi_k still equals phi_{k-1}.
        seeds.append(np.isfinite(initial) & (phi == initial))
        if not math.isfinite(stage.value):
            blocked = k
        else:
            initial = np.where(target, phi, np.inf)

    path = None if blocked is not None else _extract_path(grid, source, stages, seeds)
    return OpenLoopSolution(
        grid=grid, capture_time=capture_time, stages=tuple(stages), path=path, blocked_stage=blocked
    )


def _capture_time(grid: Grid, defenders, order: int) -> np.ndarray:
    """psi^c = min over defenders of each one's time to capture (4.1.5).

    The marching kernels release the GIL, so defenders run on parallel threads.
    """
    hx, hy = grid.spacing

    def one(defender):
        position, speed, radius = defender
        psi = fmm.march(speed, hx, hy, fmm.point_source(grid, position, speed), order=order)
        return fmm.time_to_capture(psi, (hx, hy), radius)

    if not defenders:
        return np.full(grid.shape, np.inf)
    if len(defenders) == 1:
        return one(defenders[0])
    with ThreadPoolExecutor(min(len(defenders), os.cpu_count() or 1)) as pool:
        maps = list(pool.map(one, defenders))
    for m in maps[1:]:
        np.minimum(maps[0], m, out=maps[0])
    return maps[0]


def _stage(grid: Grid, phi: np.ndarray, target: np.ndarray) -> StageSolution:
    safe = np.isfinite(phi)
    nodes = np.flatnonzero(target)
    times = phi.ravel()[nodes]
    best = int(np.argmin(times))
    value = float(times[best])
    goal: tuple[float, float] | None = None
    if math.isfinite(value):
        x, y = grid.point(np.unravel_index(nodes[best], grid.shape))
        goal = (float(x), float(y))
    return StageSolution(phi=phi, safe=safe, value=value, safe_area=float(safe.sum()) * grid.cell_area, goal=goal)


def _empty_stage(grid: Grid) -> StageSolution:
    return StageSolution(
        phi=np.full(grid.shape, np.inf),
        safe=np.zeros(grid.shape, dtype=bool),
        value=math.inf,
        safe_area=0.0,
        goal=None,
    )


def _extract_path(grid, attacker, stages, seeds) -> OpenLoopPath:
    """Descend from the last goal through each stage back to the attacker (4.2.2)."""
    pieces = []
    start = stages[-1].goal
    for k in range(len(stages) - 1, -1, -1):
        if k:
            d = descend(grid, stages[k].phi, start, seeds=seeds[k])
        else:
            d = descend(grid, stages[k].phi, start, source=attacker)
        if not d.reached:
            raise RuntimeError(f"the optimal path could not be traced back through stage {k + 1}")
        pieces.append((d.points[::-1], d.values[::-1]))
        start = tuple(d.points[-1])
    pieces.reverse()
    points: list[np.ndarray] = []
    times: list[np.ndarray] = []
    starts: list[int] = []
    for p, t in pieces:
        if times:
            # The junction opens this stage. Interpolation near it can put the
            # last vertices of the previous stage at or after this stage's
            # start time: keep only those strictly before it.
            n = int(np.searchsorted(times[-1][:-1], t[0]))
            points[-1], times[-1] = points[-1][:n], times[-1][:n]
        starts.append(sum(len(a) for a in times))
        points.append(p)
        times.append(t)
    return OpenLoopPath(points=np.vstack(points), times=np.concatenate(times), stage_starts=tuple(starts))


def _check_defender(grid: Grid, defender: Defender, k: int):
    name = f"defender {k + 1}"
    position = _check_point(grid, defender.position, name)
    speed = _check_speed(grid, defender.speed, f"{name} speed")
    _check_passable(grid, position, speed, name)
    return position, speed, non_negative(defender.capture_radius, f"{name} capture radius")


def _check_point(grid: Grid, point, name: str) -> np.ndarray:
    p = np.asarray(point, dtype=np.float64)
    if p.shape != (2,) or not np.isfinite(p).all():
        text = ", ".join(f"{float(c):g}" for c in np.ravel(p))
        raise InputError(f"{name} position ({text}) is not a finite (x, y) point")
    if not grid.contains(p):
        lo, hi = grid.lo, grid.hi
        raise InputError(
            f"{name} at ({p[0]:g}, {p[1]:g}) lies outside the grid [{lo[0]:g}, {hi[0]:g}] x [{lo[1]:g}, {hi[1]:g}]"
        )
    return p


def _check_passable(grid: Grid, point: np.ndarray, speed: np.ndarray, name: str) -> None:
    if speed[grid.nearest_index(point)] <= 0:
        raise InputError(f"{name} at ({point[0]:g}, {point[1]:g}) is on an impassable node (speed 0)")


def _check_speed(grid: Grid, speed, name: str) -> np.ndarray:
    speed = np.asarray(speed, dtype=np.float64)
    if speed.shape != grid.shape:
        raise InputError(f"{name} has shape {speed.shape} but the grid has shape {grid.shape}")
    if not (np.isfinite(speed) & (speed >= 0)).all():
        raise InputError(f"{name} has a negative, NaN or infinite value")
    return speed


def _check_target(grid: Grid, target, k: int) -> np.ndarray:
    target = np.asarray(target)
    if target.shape != grid.shape:
        raise InputError(f"target {k + 1} has shape {target.shape} but the grid has shape {grid.shape}")
    target = target.astype(bool)
    if not target.any():
        raise InputError(f"target {k + 1} is empty")
    return target
