"""Drawing a map onto matplotlib axes, as the base layer of every map figure.

The map sits below zorder 1 so that whatever a caller plots afterwards
(reachable sets, paths, agents) with matplotlib's default zorders stays on top.
"""

from __future__ import annotations

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.patches import PathPatch
from matplotlib.path import Path
from shapely.geometry import MultiPolygon

from bearcat.maps.model import Map

SPEED_COLOURS = "YlGn_r"
"""Pale for fast ground (walkways), darker green for denser vegetation."""
OBSTACLE_COLOUR = "0.3"
ROLE_COLOURS = {"flag": "tab:red", "return": "tab:blue", "target": "tab:purple"}
TEAM_COLOURS = ("tab:orange", "tab:cyan", "tab:olive", "tab:pink")
"""Sides, told apart by team in order of appearance."""


def _path(geometry) -> Path:
    polygons = geometry.geoms if isinstance(geometry, MultiPolygon) else [geometry]
    vertices, codes = [], []
    for polygon in polygons:
        for ring in (polygon.exterior, *polygon.interiors):
            xy = np.asarray(ring.coords)
            vertices.append(xy)
            codes.append([Path.MOVETO] + [Path.LINETO] * (len(xy) - 2) + [Path.CLOSEPOLY])
    return Path(np.concatenate(vertices), np.concatenate(codes))


def _patch(ax, geometry, **style) -> None:
    ax.add_patch(PathPatch(_path(geometry), **style))


def draw_map(ax, map: Map, *, zones: bool = True, labels: bool = True) -> ScalarMappable | None:
    """Draw ``map`` in metres on ``ax``: area, terrain zones, obstacles, regions.

    Returns the speed colour scale when zones are drawn, for the caller's
    colourbar (``fig.colorbar(scale, ax=ax, label="speed factor")``).
    """
    scale = ScalarMappable(Normalize(0.0, 1.0), SPEED_COLOURS) if zones else None
    area_face = "white" if scale is None else scale.to_rgba(np.asarray(map.area_speed))
    _patch(ax, map.area, facecolor=area_face, edgecolor="none", zorder=0.1)
    if scale is not None:
        for zone in map.zones:
            _patch(ax, zone.geometry, facecolor=scale.to_rgba(np.asarray(zone.speed)), edgecolor="none", zorder=0.2)
    _patch(ax, map.area, facecolor="none", edgecolor="black", linewidth=1.2, zorder=0.6)
    assert map.obstacle_names is not None  # a Map fills them in
    for obstacle, name in zip(map.obstacles, map.obstacle_names):
        # Edges in the fill colour hide the seams between abutting obstacles.
        _patch(ax, obstacle, facecolor=OBSTACLE_COLOUR, edgecolor=OBSTACLE_COLOUR, linewidth=0.5, zorder=0.5)
        if labels and name:
            spot = obstacle.representative_point()
            ax.text(spot.x, spot.y, name, color="white", fontsize=6, ha="center", va="center", zorder=0.9)
    teams = list(dict.fromkeys(r.team for r in map.regions.values() if r.role == "side"))
    for region in map.regions.values():
        if region.role == "side":
            colour = TEAM_COLOURS[teams.index(region.team) % len(TEAM_COLOURS)]
        else:
            colour = ROLE_COLOURS[region.role]
        _patch(ax, region.geometry, facecolor=colour, alpha=0.2, edgecolor="none", zorder=0.7)
        _patch(ax, region.geometry, facecolor="none", edgecolor=colour, linewidth=1.5, zorder=0.8)
        if labels:
            spot = region.geometry.representative_point()
            label = f"{region.name}\n({region.team})" if region.team else region.name
            ax.text(
                spot.x,
                spot.y,
                label,
                color=colour,
                fontsize=8,
                fontweight="bold",
                ha="center",
                va="center",
                zorder=0.9,
            )
    xmin, ymin, xmax, ymax = map.bounds
    margin = 0.02 * max(xmax - xmin, ymax - ymin)
    ax.set_xlim(xmin - margin, xmax + margin)
    ax.set_ylim(ymin - margin, ymax + margin)
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    return scale
