"""The calibration's figure: each answer's error in the value against the
reports' age, with the margin each age bin was given, one panel per phase.
Only the CLI renders it (headless Agg backend)."""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np


def calibration_figure(scores, calibration):
    """Errors (true value less estimated) by report age, and the margins as steps."""
    phases = [p for p in calibration.margins if any(s.phase == p for s in scores)] or ["capture"]
    fig, axes = plt.subplots(1, len(phases), figsize=(6.0 * len(phases), 4.2), squeeze=False)
    edges = np.array(calibration.edges)
    finite_top = max([s.age for s in scores] + [float(edges[-2]) + 1.0])
    for ax, phase in zip(axes[0], phases):
        mine = [s for s in scores if s.phase == phase]
        ax.scatter([s.age for s in mine], [s.error for s in mine], s=2, alpha=0.15, color="tab:blue", label="answers")
        for k, margin in enumerate(calibration.margins.get(phase, ())):
            if margin is None:
                continue
            high = edges[k + 1] if math.isfinite(edges[k + 1]) else finite_top
            ax.hlines(margin, edges[k], high, color="tab:red", linewidth=2)
        ax.plot([], [], color="tab:red", linewidth=2, label=f"margin at alpha {calibration.alpha:g}")
        ax.axhline(0.0, color="grey", linewidth=0.8)
        ax.set_xlabel("age of the older report (s)")
        ax.set_ylabel("V(true) - V(estimated), m")
        ax.set_title(f"{phase} phase: {len(mine)} answers")
        ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    return fig
