"""The studies' figures, from their summary rows: rates with their 95 %
intervals, so a difference that the games do not support shows as
overlapping bars. Only the CLI renders them (headless Agg backend)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

GUIDANCE_COLOURS = {
    "plain": "tab:red",
    "worst-case": "tab:blue",
    "worst-case, age only": "tab:green",
    "calibrated": "tab:orange",
    "human": "tab:purple",
}


def _errors(rows, rate: str, interval: str) -> tuple[np.ndarray, np.ndarray]:
    """Rates and their asymmetric error bars, in percent."""
    values = np.array([100 * r[rate] for r in rows])
    low = np.array([100 * r[interval][0] for r in rows])
    high = np.array([100 * r[interval][1] for r in rows])
    return values, np.vstack([values - low, high - values])


def holding_figure(rows):
    """One panel per network: how often the aided defender holds against the
    report rate, one line per guidance."""
    networks = list(dict.fromkeys(f"{r['netem']}/{r['transport']}" for r in rows))
    fig, axes = plt.subplots(1, len(networks), figsize=(4.2 * len(networks), 4.2), squeeze=False, sharey=True)
    for ax, network in zip(axes[0], networks):
        for k, guidance in enumerate(dict.fromkeys(r["guidance"] for r in rows)):
            mine = sorted(
                (r for r in rows if r["guidance"] == guidance and f"{r['netem']}/{r['transport']}" == network),
                key=lambda r: r["rate"],
            )
            values, errors = _errors(mine, "defender_win_rate", "defender_win_interval")
            rates = np.array([r["rate"] for r in mine]) * (1 + 0.04 * (k - 1))  # side by side
            ax.errorbar(
                rates, values, yerr=errors, marker="o", capsize=3, label=guidance, color=GUIDANCE_COLOURS.get(guidance)
            )
        ax.axhline(95, color="grey", linestyle=":", linewidth=1)
        ax.set_xscale("log")
        ax.set_xticks([1, 2, 5, 10], ["1", "2", "5", "10"])
        ax.set_xlabel("phones report (Hz)")
        ax.set_title(network)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("defender holds (%), 95 % interval")
    axes[0][0].legend(loc="lower right")
    fig.suptitle("the aided defender from the fake-out's starts")
    fig.tight_layout()
    return fig


def go_no_go_figure(rows):
    """False-go rate and attacker win rate per network, bars per guidance."""
    networks = list(dict.fromkeys(f"{r['netem']}/{r['transport']}" for r in rows))
    guidance = list(dict.fromkeys(r["guidance"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    width = 0.8 / len(guidance)
    x = np.arange(len(networks))
    for panel, (rate, interval, title) in zip(
        axes,
        [
            ("false_go_rate", "false_go_interval", "false goes (% of goes)"),
            ("attacker_win_rate", "attacker_win_interval", "attacker wins (% of games)"),
        ],
    ):
        for k, g in enumerate(guidance):
            mine = [
                next((r for r in rows if r["guidance"] == g and f"{r['netem']}/{r['transport']}" == n), None)
                for n in networks
            ]
            shown = [r for r in mine if r is not None and r[rate] is not None]
            positions = [x[i] + (k - (len(guidance) - 1) / 2) * width for i, r in enumerate(mine) if r in shown]
            values, errors = _errors(shown, rate, interval) if shown else ([], None)
            panel.bar(positions, values, width, yerr=errors, capsize=3, label=g, color=GUIDANCE_COLOURS.get(g))
        panel.set_xticks(x, networks)
        panel.set_title(title)
        panel.grid(axis="y", alpha=0.3)
    axes[0].legend()
    fig.suptitle("go/no-go: the attacker commits when its display says go")
    fig.tight_layout()
    return fig


def fake_out_figure(rows):
    """One heatmap per report rate: the attacker's win rate against the
    unaided defender by marking distance (rows) and reaction time (columns),
    the aided defenders (plain, worst-case, calibrated) as the bottom rows."""
    people = [r for r in rows if r["defender"] == "human"]
    rows = [r for r in rows if r["defender"] != "human"]
    rates = sorted({r["rate"] for r in rows}) or [None]
    reactions = sorted({r["reaction"] for r in rows})
    fig, axes = plt.subplots(1, len(rates), figsize=(5.2 * len(rates) + 1.6, 4.8), squeeze=False, layout="constrained")
    image = None
    for k, (ax, rate) in enumerate(zip(axes[0], rates)):
        at_rate = [r for r in rows if r["rate"] == rate]
        if not at_rate:
            ax.axis("off")
            continue
        kinds = list(dict.fromkeys((r["defender"], r["marking"]) for r in at_rate))
        kinds.sort(key=lambda k: (k[1] is None, k[1] or 0))
        grid = np.full((len(kinds), len(reactions)), np.nan)
        for r in at_rate:
            i, j = kinds.index((r["defender"], r["marking"])), reactions.index(r["reaction"])
            grid[i, j] = 100 * r["attacker_win_rate"]
            low, high = (100 * v for v in r["attacker_win_interval"])
            ax.text(j, i, f"{grid[i, j]:.0f}%\n{low:.0f}-{high:.0f}", ha="center", va="center", fontsize=8)
        image = ax.imshow(grid, cmap="RdBu_r", vmin=0, vmax=100, aspect="auto")
        ax.set_xticks(range(len(reactions)), [f"{t:g}" for t in reactions])
        names = [f"marks {m:g} m" if m is not None else d for d, m in kinds]
        ax.set_yticks(range(len(kinds)), names if k == 0 else [])
        ax.set_xlabel("defender's reaction time (s)")
        ax.set_title(f"phones report at {rate:g} Hz")
    if image is not None:
        fig.colorbar(image, ax=axes[0].tolist(), label="attacker wins (%)")
    title = "the fake-out: attacker wins against the unaided defender, and the aided ones"
    for r in people:
        low, high = (100 * v for v in r["attacker_win_interval"])
        title += (
            f"\na person as the defender ({r['games']} games, phones at {r['rate']:g} Hz): "
            f"attacker wins {100 * r['attacker_win_rate']:.0f}% ({low:.0f}-{high:.0f})"
        )
    fig.suptitle(title)
    return fig


def search_figure(rows):
    """Attacker win rate and median time to find, per search strategy."""
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8))
    names = [r["search"] for r in rows]
    values = np.array([100 * r["attacker_win_rate"] for r in rows])
    low = np.array([100 * r["win_rate_95"][0] for r in rows])
    high = np.array([100 * r["win_rate_95"][1] for r in rows])
    axes[0].bar(names, values, yerr=np.vstack([values - low, high - values]), capsize=3)
    axes[0].set_title("attacker wins (%), 95 % interval")
    axes[1].bar(names, [r["median_time_to_find"] or 0 for r in rows])
    axes[1].set_title("median time to find the defender (s)")
    fig.tight_layout()
    return fig


FIGURES = {"fake-out": fake_out_figure, "holding": holding_figure, "go-no-go": go_no_go_figure, "search": search_figure}
