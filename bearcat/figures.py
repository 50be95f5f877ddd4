"""Matplotlib figures the commands write, drawn on the map the way the thesis drew them.

Only the CLI renders figures; importing this module selects the headless Agg
backend so that no command ever needs a display.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from maps import Map, Raster  # noqa: E402
from maps.plot import draw_map  # noqa: E402
from solvers.openloop import OpenLoopSolution  # noqa: E402

STAGE_COLOURS = ("tab:red", "tab:purple", "tab:orange", "tab:brown", "tab:pink")


def _contour(ax, raster: Raster, field: np.ndarray, **kwargs):
    """Contour a node field; arrays are ``[ix, iy]`` so they are transposed for matplotlib."""
    x, y = raster.grid.axes()
    return ax.contour(x, y, field.T, **kwargs)


def openloop_figure(
    game_map: Map,
    raster: Raster,
    solution: OpenLoopSolution,
    targets: list[np.ndarray],
    attacker: tuple[float, float],
    defenders: list[tuple[float, float]],
    report: dict,
):
    """One panel per stage, as thesis Fig. 4.4/4.5: the stage's safe-reachable set
    S_k (its boundary, with level lines of phi_k inside), the stage's stretch of the
    path solid and the rest dotted, the defenders and the targets."""
    stages = solution.stages
    fig, axes = plt.subplots(
        1, len(stages), figsize=(6.2 * len(stages), 6.8), squeeze=False, layout="constrained"
    )
    path = solution.path
    cuts = list(path.stage_starts) + [len(path.points) - 1] if path is not None else []
    for k, (ax, stage) in enumerate(zip(axes[0], stages)):
        draw_map(ax, game_map, labels=True)
        colour = STAGE_COLOURS[k % len(STAGE_COLOURS)]
        if stage.safe.any():
            # Only where S_k meets free space: obstacles are outside S_k by
            # construction, and outlining every building again says nothing.
            inside = np.where(raster.free, stage.safe.astype(float), np.nan)
            _contour(ax, raster, inside, levels=[0.5], colors=[colour], linewidths=1.8)
            finite = np.where(stage.safe, stage.phi, np.nan)
            levels = np.linspace(np.nanmin(finite), np.nanmax(finite), 12)[1:-1]
            if levels.size and levels[0] < levels[-1]:
                _contour(ax, raster, finite, levels=levels, colors=[colour], linewidths=0.5, alpha=0.45)
        _contour(ax, raster, targets[k].astype(float), levels=[0.5], colors=["tab:green"], linewidths=2.0)
        if path is not None:
            ax.plot(path.points[:, 0], path.points[:, 1], ":", color="black", linewidth=1.0)
            segment = path.points[cuts[k] : cuts[k + 1] + 1]
            ax.plot(segment[:, 0], segment[:, 1], "-", color="black", linewidth=2.0, label="safe path")
        ax.plot(*attacker, "o", color="tab:blue", markersize=9, markeredgecolor="white", label="attacker")
        for x, y in defenders:
            ax.plot(x, y, "^", color="tab:red", markersize=10, markeredgecolor="white")
        entry = report["stages"][k]
        value = "unreachable" if entry["value_s"] is None else f"{entry['value_s']:.1f} s"
        ax.set_title(f"stage {k + 1}: to {entry['target']}, attacker {entry['attacker_speed']:g} m/s\n"
                     f"value {value}, S_{k + 1} area {entry['safe_area_m2']:.0f} m$^2$")
    verdict = "safe path found" if solution.reached else f"no safe path (stage {report['blocked_stage']})"
    fig.suptitle(f"open-loop reach-avoid on {game_map.name}: {verdict}")
    return fig
