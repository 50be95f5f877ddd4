"""The backflip's figures, drawn as thesis 6.1 drew them: the composite
capture sets in the attitude plane (Fig. 6.2, with flown paths Fig. 6.6a)
and the unsafe sets in the height plane (Fig. 6.3, with the switching
points Fig. 6.8). Angles are shown in degrees.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.artist import Artist
from matplotlib.patches import Patch, Rectangle

from bearcat.solvers.maneuvers.backflip import BackflipSets, TargetBox
from bearcat.solvers.maneuvers.backflip_flight import Flight

DEG = 180 / np.pi
MODE_COLOURS = {"impulse": "tab:red", "drift": "tab:blue", "recovery": "tab:green"}
TARGETS = (("T1", "t1", "tab:red"), ("T2", "t2", "tab:blue"), ("T3", "t3", "tab:green"))
UNSAFE_COLOURS = {"K1": "#fdd0a2", "K2": "#fd8d3c", "K3": "#a63603"}
UNSAFE_LABELS = {
    "K1": "K1: unsafe to start the drift",
    "K2": "K2: unsafe to start the recovery",
    "K3": "K3: unsafe in the recovery",
}


def design_figure(sets: BackflipSets, flights: list[Flight] | None = None):
    """Fig. 6.2 beside Fig. 6.3; with ``flights``, their paths and switches
    over both (Figs. 6.6a and 6.8)."""
    fig, (attitude, height) = plt.subplots(1, 2, figsize=(14, 6), layout="constrained")
    _attitude_panel(attitude, sets)
    _height_panel(height, sets)
    if flights:
        _flown(attitude, height, flights)
    return fig


def _attitude_panel(ax, sets: BackflipSets) -> None:
    grid = sets.design.attitude_grid
    phi, rate = (a * DEG for a in grid.axes())
    handles: list[Artist] = []
    for mode in ("recovery", "drift", "impulse"):
        value = sets.capture[mode].value
        colour = MODE_COLOURS[mode]
        ax.contourf(phi, rate, value.T, levels=[-np.inf, 0], colors=[colour], alpha=0.18)
        ax.contour(phi, rate, value.T, levels=[0], colors=[colour], linewidths=1.2)
        target = {"impulse": "T1", "drift": "T2", "recovery": "T3"}[mode]
        handles.append(Patch(color=colour, alpha=0.35, label=f"RA_T({target}): {mode} capture set"))
    ax.contour(phi, rate, sets.reach.T, levels=[0], colors=["black"], linestyles="--", linewidths=1.2)
    handles.append(plt.Line2D([], [], color="black", linestyle="--", label="Reach_T4(T1): motors turning off"))
    for name, attr, colour in TARGETS:
        _box(ax, getattr(sets.design, attr), colour, name)
    _box(ax, sets.design.start, "grey", "hover")
    ax.set(
        xlabel="phi (deg)",
        ylabel="phi' (deg/s)",
        title="Composite capture sets (thesis Fig. 6.2)",
        xlim=(phi[0], phi[-1]),
        ylim=(rate[0], rate[-1]),
    )
    ax.legend(handles=handles, loc="lower left", fontsize=8)


def _box(ax, box: TargetBox, colour: str, name: str) -> None:
    (a0, a1), (r0, r1) = (np.array(box.angle) * DEG, np.array(box.rate) * DEG)
    ax.add_patch(Rectangle((a0, r0), a1 - a0, r1 - r0, fill=False, edgecolor=colour, linewidth=2.0))
    ax.annotate(name, (a1, r1), xytext=(3, 3), textcoords="offset points", color=colour, fontsize=10, weight="bold")


def _height_panel(ax, sets: BackflipSets) -> None:
    y, v = sets.design.vertical_grid.axes()
    handles = []
    for name in ("K1", "K2", "K3"):
        value = sets.unsafe[name]
        ax.contourf(y, v, value.T, levels=[-np.inf, 0], colors=[UNSAFE_COLOURS[name]])
        handles.append(Patch(color=UNSAFE_COLOURS[name], label=UNSAFE_LABELS[name]))
    ax.set(
        xlabel="y (m)",
        ylabel="y' (m/s)",
        title="Unsafe vertical sets (thesis Fig. 6.3)",
        xlim=(y[0], y[-1]),
        ylim=(v[0], v[-1]),
    )
    ax.legend(handles=handles, loc="upper left", fontsize=8)


def _flown(attitude, height, flights: list[Flight]) -> None:
    for flight in flights:
        path = flight.path
        flipping = path[:, 7] >= 1
        attitude.plot(path[flipping, 5] * DEG, path[flipping, 6] * DEG, color="black", linewidth=0.6, alpha=0.6)
        height.plot(path[:, 3], path[:, 4], color="black", linewidth=0.5, alpha=0.4)
        to_drift, to_recovery = flight.switches[1], flight.switches[2]
        attitude.plot(to_drift[1] * DEG, to_drift[2] * DEG, "kD", markersize=5)
        attitude.plot(to_recovery[1] * DEG, to_recovery[2] * DEG, "ks", markersize=5)
        height.plot(to_drift[3], to_drift[4], "o", color="tab:cyan", markeredgecolor="black", markersize=5)
        height.plot(to_recovery[3], to_recovery[4], "o", color="tab:orange", markeredgecolor="black", markersize=5)
    attitude.set_title(f"{len(flights)} flips through the capture sets (thesis Fig. 6.6a)")
    height.set_title("Heights at the switches (thesis Fig. 6.8)")
    attitude.legend(
        handles=[
            *attitude.get_legend().legend_handles,
            plt.Line2D([], [], color="black", marker="D", linestyle="none", label="switch to the drift"),
            plt.Line2D([], [], color="black", marker="s", linestyle="none", label="switch to the recovery"),
        ],
        loc="lower left",
        fontsize=8,
    )
    height.legend(
        handles=[
            *height.get_legend().legend_handles,
            plt.Line2D([], [], color="tab:cyan", marker="o", linestyle="none", label="entering the drift"),
            plt.Line2D([], [], color="tab:orange", marker="o", linestyle="none", label="entering the recovery"),
        ],
        loc="upper left",
        fontsize=8,
    )
