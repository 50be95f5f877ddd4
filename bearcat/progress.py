"""Progress bars on stderr for solves that the field commands set off."""

from __future__ import annotations

import sys


def solve_bars():
    """A ``progress(name, t, horizon, change)`` callback drawing one bar per
    solved set, in seconds of game time; ``progress.close()`` closes the bars
    of sets that converged before their horizon."""
    from tqdm import tqdm

    bars: dict = {}

    def update(name, t, horizon, change):
        bar = bars.get(name)
        if bar is None:
            bar = bars[name] = tqdm(
                total=round(horizon, 2),
                desc=f"solving the {name} set",
                file=sys.stderr,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s of game time [{elapsed}]",
            )
        bar.update(round(t - bar.n, 2))
        if t >= horizon - 1e-9:
            bar.close()

    update.close = lambda: [bar.close() for bar in bars.values()]
    return update
