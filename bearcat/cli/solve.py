"""``bearcat solve ...``: run a solver once on a map and report the result.

This module turns command-line words into solver inputs (rasters, masks,
speed maps) and the solver's result into text, JSON and a figure; the
numerics live in ``solvers``.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bearcat.cli import arguments
from bearcat.cli.output import Output, add_json_option
from bearcat.maps import Map, MapError, Raster, load_map, rasterize
from bearcat.solvers.marching.openloop import Defender, OpenLoopSolution, solve_openloop

#: Default grid: this many cells along the longer side of the map, so a
#: 10 m maze and a 400 m campus both get a useful resolution.
DEFAULT_CELLS = 400


@dataclass(frozen=True)
class TargetSpec:
    """A stage target as the user named it: a map region or a disk."""

    text: str
    region: str | None = None
    disk: tuple[float, float, float] | None = None

    def mask(self, game_map: Map, raster: Raster, stage: int) -> np.ndarray:
        if self.region is not None:
            mask = raster.masks[game_map.region(self.region).name]
        else:
            assert self.disk is not None  # a target is a region or a disk
            cx, cy, radius = self.disk
            x, y = raster.grid.mesh()
            mask = (x - cx) ** 2 + (y - cy) ** 2 <= radius**2
        mask = mask & raster.free
        if not mask.any():
            raise MapError(
                f"target {stage} ({self.text}) has no free grid node inside the area of map "
                f"{game_map.name} at spacing {raster.grid.spacing[0]:g} m"
            )
        return mask


def target_spec(text: str) -> TargetSpec:
    """``REGION`` (a region name of the map) or ``X,Y,R`` (a disk in map metres)."""
    if "," not in text:
        return TargetSpec(text, region=text)
    x, y, r = arguments.numbers(text, (3,), "target")
    if r <= 0:
        raise argparse.ArgumentTypeError(f"target {text!r} needs a radius above zero")
    return TargetSpec(text, disk=(x, y, r))


def defender_spec(text: str) -> tuple[float, float, float]:
    """``X,Y`` or ``X,Y,SPEED`` (m/s on full-speed terrain, default 1)."""
    values = arguments.numbers(text, (2, 3), "defender")
    speed = values[2] if len(values) == 3 else 1.0
    if speed <= 0:
        raise argparse.ArgumentTypeError(f"defender {text!r} needs a speed above zero")
    return values[0], values[1], speed


def register(commands: arguments.Commands) -> None:
    """``solve openloop``; ``cli.ctf`` and ``cli.maneuver`` add the other games."""
    openloop = commands.games("solve").add_parser(
        "openloop",
        help="1-vs-many open-loop reach-avoid: safe-reachable sets and a guaranteed-safe path",
        description=(
            "Modified fast marching (thesis ch. 4): the attacker's safe-reachable set against "
            "every defender, the open-loop value of each stage and the optimal path through "
            "the targets in order."
        ),
    )
    openloop.add_argument("--map", required=True, help="built-in map name or path to a GeoJSON map")
    openloop.add_argument("--attacker", required=True, type=arguments.point, metavar="X,Y")
    openloop.add_argument(
        "--defender",
        action="extend",
        nargs="+",
        type=defender_spec,
        default=[],
        metavar="X,Y[,SPEED]",
        help="a defender (repeatable); SPEED in m/s on full-speed terrain, default 1",
    )
    openloop.add_argument(
        "--target",
        action="extend",
        nargs="+",
        type=target_spec,
        required=True,
        metavar="REGION|X,Y,R",
        help="the target of each stage, in order",
    )
    openloop.add_argument(
        "--stage-speed",
        action="extend",
        nargs="+",
        type=arguments.positive,
        metavar="F",
        help="attacker speed in m/s on full-speed terrain, one per stage or one for all (default 1)",
    )
    openloop.add_argument(
        "--capture-radius",
        type=arguments.non_negative,
        default=0.0,
        metavar="R",
        help="capture radius in metres (default 0)",
    )
    openloop.add_argument(
        "--spacing",
        type=arguments.positive,
        metavar="M",
        help=f"grid spacing in metres (default: the longer side of the map / {DEFAULT_CELLS})",
    )
    openloop.add_argument("--order", type=int, choices=(1, 2), default=1, help="fast-marching order")
    openloop.add_argument("--plot", type=Path, metavar="PNG", help="write a figure of the sets and path")
    add_json_option(openloop, "the result")
    openloop.set_defaults(run=run_openloop)


def stage_speeds(args, stages: int) -> list[float]:
    speeds = args.stage_speed or [1.0]
    if len(speeds) == 1:
        return speeds * stages
    if len(speeds) != stages:
        raise arguments.UsageError(
            f"--stage-speed gives {len(speeds)} speeds for {stages} targets; give one or one per target"
        )
    return speeds


def run_openloop(args) -> int:
    out = Output(args.json)
    game_map = load_map(args.map)
    game_map.check_position(args.attacker, "attacker")
    for k, (x, y, _) in enumerate(args.defender, start=1):
        game_map.check_position((x, y), f"defender {k}")
    speeds = stage_speeds(args, len(args.target))
    xmin, ymin, xmax, ymax = game_map.bounds
    spacing = args.spacing or max(xmax - xmin, ymax - ymin) / DEFAULT_CELLS
    raster = rasterize(game_map, spacing)
    targets = [spec.mask(game_map, raster, k) for k, spec in enumerate(args.target, start=1)]
    defenders = [
        Defender(position=(x, y), speed=speed * raster.speed, capture_radius=args.capture_radius)
        for x, y, speed in args.defender
    ]
    solution = solve_openloop(
        raster.grid,
        args.attacker,
        [speed * raster.speed for speed in speeds],
        targets,
        defenders,
        order=args.order,
    )
    report = openloop_report(args, game_map, spacing, speeds, solution)
    out.say(openloop_summary(report))
    out.json(report)
    if args.plot is not None:
        from bearcat.figures.games import openloop_figure

        figure = openloop_figure(
            game_map, raster, solution, targets, args.attacker, [(x, y) for x, y, _ in args.defender], report
        )
        out.figure(figure, args.plot, dpi=110)
    return 0


def _finite_or_none(value: float) -> float | None:
    return round(float(value), 4) if math.isfinite(value) else None


def openloop_report(args, game_map: Map, spacing: float, speeds, solution: OpenLoopSolution) -> dict:
    """The JSON-ready result: per stage the value (s), safe-set area (m^2) and path."""
    path = solution.path
    bounds = list(path.stage_starts) + [len(path.points) - 1] if path is not None else []
    stages = []
    for k, (spec, speed, stage) in enumerate(zip(args.target, speeds, solution.stages)):
        entry = {
            "target": spec.text,
            "attacker_speed": speed,
            "value_s": _finite_or_none(stage.value),
            "safe_area_m2": round(float(stage.safe_area), 1),
            "goal": None if stage.goal is None else [round(float(c), 3) for c in stage.goal],
        }
        if path is not None:
            first, last = bounds[k], bounds[k + 1]
            points = path.points[first : last + 1]
            entry["path"] = {
                "length_m": round(float(np.sum(np.hypot(*np.diff(points, axis=0).T))), 2),
                "points": [[round(float(x), 3), round(float(y), 3)] for x, y in points],
                "times_s": [round(float(t), 4) for t in path.times[first : last + 1]],
            }
        stages.append(entry)
    return {
        "map": game_map.name,
        "spacing_m": spacing,
        "grid_shape": list(solution.grid.shape),
        "attacker": list(args.attacker),
        "defenders": [{"position": [x, y], "speed": s} for x, y, s in args.defender],
        "capture_radius_m": args.capture_radius,
        "reached": solution.reached,
        "blocked_stage": None if solution.blocked_stage is None else solution.blocked_stage + 1,
        "value_s": _finite_or_none(solution.value),
        "stages": stages,
    }


def openloop_summary(report: dict) -> str:
    lines = [
        f"map {report['map']}, grid {report['grid_shape'][0]} x {report['grid_shape'][1]} "
        f"at {report['spacing_m']:g} m, {len(report['defenders'])} defender(s), "
        f"capture radius {report['capture_radius_m']:g} m"
    ]
    for k, stage in enumerate(report["stages"], start=1):
        value = "unreachable" if stage["value_s"] is None else f"{stage['value_s']:.2f} s"
        line = f"stage {k} -> {stage['target']}: value {value}, safe-reachable area {stage['safe_area_m2']:.0f} m^2"
        if "path" in stage:
            line += f", path {stage['path']['length_m']:.1f} m"
        lines.append(line)
    if report["reached"]:
        lines.append(f"safe path found: every target reached by {report['value_s']:.2f} s whatever the defenders do")
    else:
        lines.append(
            f"no safe path: the target of stage {report['blocked_stage']} is not safe-reachable "
            "(some defender strategy can intercept every attacker path)"
        )
    return "\n".join(lines)
