"""Matplotlib figures the commands write, drawn on the map the way the thesis drew them.

Only the CLI renders figures; importing this module selects the headless Agg
backend so that no command ever needs a display.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from bearcat.maps import Map, Raster
from bearcat.maps.plot import draw_map
from bearcat.solvers.marching.openloop import OpenLoopSolution

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
    fig, axes = plt.subplots(1, len(stages), figsize=(6.2 * len(stages), 6.8), squeeze=False, layout="constrained")
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
        ax.set_title(
            f"stage {k + 1}: to {entry['target']}, attacker {entry['attacker_speed']:g} m/s\n"
            f"value {value}, S_{k + 1} area {entry['safe_area_m2']:.0f} m$^2$"
        )
    verdict = "safe path found" if solution.reached else f"no safe path (stage {report['blocked_stage']})"
    fig.suptitle(f"open-loop reach-avoid on {game_map.name}: {verdict}")
    return fig


def _region(ax, guidance, values: np.ndarray, side: str, colour: str, label: str) -> None:
    """Fill a slice's region (``values <= 0`` for the attacker's, ``> 0``
    for the defender's) with its zero level as the edge."""
    x, y = guidance.geometry.grid.axes()
    finite = float(np.max(np.abs(values))) + 1.0
    levels = [-finite, 0.0] if side == "attacker" else [0.0, finite]
    ax.contourf(x, y, values.T, levels=levels, colors=[colour], alpha=0.35)
    ax.contour(x, y, values.T, levels=[0.0], colors=[colour], linewidths=1.5)
    ax.plot([], [], "s", color=colour, alpha=0.5, label=label)


def _players(ax, attacker, defender, attacker_heading=None, defender_heading=None, scale=1.0) -> None:
    ax.plot(*attacker, "o", color="tab:blue", markersize=10, markeredgecolor="white", label="attacker", zorder=5)
    ax.plot(*defender, "^", color="tab:red", markersize=11, markeredgecolor="white", label="defender", zorder=5)
    for (px, py), heading, colour in (
        (attacker, attacker_heading, "tab:blue"),
        (defender, defender_heading, "tab:red"),
    ):
        if heading is not None:
            ax.annotate(
                "",
                xy=(px + scale * heading[0], py + scale * heading[1]),
                xytext=(px, py),
                arrowprops=dict(arrowstyle="-|>", color=colour, linewidth=2),
                zorder=6,
            )


def ctf_query_figure(
    game_map: Map, guidance, attacker, defender, report, phase, defender_values, attacker_values, set_name, disks=None
):
    """What each phone shows (thesis Fig. 3.6, 3.9): on the attacker's, the
    defender positions that win against it, R_D(x_a); on the defender's, the
    attacker positions that win against it, R_A(x_d); each with its optimal
    heading. ``disks`` (radius per player) draws where each player may be,
    for robust answers."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(12.4, 6.6), layout="constrained")
    xmin, ymin, xmax, ymax = game_map.bounds
    scale = 0.08 * max(xmax - xmin, ymax - ymin)
    defender_set = set_name.replace("_A", "_D")
    for ax, values, side, colour, label, heading in (
        (left, defender_values, "defender", "tab:red", f"{defender_set}(x_a): defender wins", "attacker"),
        (right, attacker_values, "attacker", "tab:blue", f"{set_name}(x_d): attacker wins", "defender"),
    ):
        draw_map(ax, game_map, labels=True)
        _region(ax, guidance, values, side, colour, label)
        _players(
            ax,
            attacker,
            defender,
            report.attacker_heading if heading == "attacker" else None,
            report.defender_heading if heading == "defender" else None,
            scale,
        )
        for who, centre, colour in (("attacker", attacker, "tab:blue"), ("defender", defender, "tab:red")):
            if disks is not None and disks[who] > 0:
                ax.add_patch(plt.Circle(centre, disks[who], fill=False, linestyle="--", color=colour, linewidth=1.2))
        ax.legend(loc="lower right", fontsize=8)
        ax.set_title(f"{heading}'s view: {label}")
    fig.suptitle(
        f"capture-the-flag on {game_map.name}, {phase} phase: {report.winner} wins, value {report.value:+.2f} m"
    )
    return fig


def ctf_play_figure(game_map: Map, guidance, outcome, start):
    """A closed-loop game as thesis Fig. 3.4/3.5: the defender's winning
    region for the attacker's start, then both tracks (attacker solid,
    defender dashed) with where the flag was taken."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(12.4, 6.6), layout="constrained")
    attacker, defender = outcome.attacker[0], outcome.defender[0]
    phase = outcome.phases[0]
    name = guidance.value_set(phase).name
    region = {"win": "W_D", "capture": "F_D", "return": "R_D"}[name]
    draw_map(left, game_map, labels=True)
    _region(
        left,
        guidance,
        guidance.defender_region_values(attacker, phase),
        "defender",
        "tab:red",
        f"{region}(x_a): defender wins",
    )
    _players(left, attacker, defender)
    left.legend(loc="lower right", fontsize=8)
    left.set_title(f"start: {start.winner} predicted to win (value {start.value:+.2f} m)")
    draw_map(right, game_map, labels=True)
    right.plot(outcome.attacker[:, 0], outcome.attacker[:, 1], "-", color="tab:blue", linewidth=2, label="attacker")
    right.plot(outcome.defender[:, 0], outcome.defender[:, 1], "--", color="tab:red", linewidth=2, label="defender")
    _players(right, attacker, defender)
    right.plot(*outcome.attacker[-1], "o", color="tab:blue", markersize=6)
    right.plot(*outcome.defender[-1], "^", color="tab:red", markersize=7)
    if outcome.flag_time is not None:
        k = int(np.searchsorted(outcome.times, outcome.flag_time))
        right.plot(*outcome.attacker[k], "*", color="gold", markersize=16, markeredgecolor="black", label="flag taken")
    handles, labels = right.get_legend_handles_labels()
    unique = dict(zip(labels, handles))
    right.legend(unique.values(), unique.keys(), loc="lower right", fontsize=8)
    right.set_title(f"{outcome.winner} won: {outcome.reason} at {outcome.duration:.1f} s")
    fig.suptitle(f"capture-the-flag on {game_map.name}: both players on the optimal strategies")
    return fig


def pursuit_histograms(table: dict, domains, counts):
    """Fig. 5.11: per domain, the capture-time difference area minus pure
    pursuit of each trial (negative: area pursuit was faster), one colour
    per pursuer count."""
    fig, axes = plt.subplots(1, len(domains), figsize=(5.2 * len(domains), 4.4), squeeze=False, layout="constrained")
    colours = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple")
    for ax, domain in zip(axes[0], domains):
        rows = [(n, table.get(f"{domain}/{n}")) for n in counts]
        values = [v for _, row in rows if row for v in row["differences"]]
        if not values:
            ax.set_title(f"{domain}: no captured pairs")
            continue
        bins = np.linspace(min(values), max(values), 31) if min(values) < max(values) else 10
        for k, (n, row) in enumerate(rows):
            if row and row["differences"]:
                ax.hist(
                    row["differences"],
                    bins=bins,
                    histtype="step",
                    linewidth=1.8,
                    color=colours[k % len(colours)],
                    label=f"{n} pursuer{'s' if n > 1 else ''}: {row['area_faster_percent']:.1f}% faster",
                )
        ax.axvline(0.0, color="black", linewidth=0.8)
        ax.set_xlabel("capture time, area minus pure pursuit")
        ax.set_ylabel("trials")
        ax.set_title(domain)
        ax.legend(fontsize=8)
    fig.suptitle("safe-reachable-area pursuit against pure pursuit (thesis Fig. 5.11)")
    return fig
