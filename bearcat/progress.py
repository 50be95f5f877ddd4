"""Progress bars on stderr for solves that the field commands set off."""

from __future__ import annotations

import sys


def solve_bars():
    """A ``progress(name, t, horizon, change)`` callback drawing one bar per
    solved set, in seconds of game time, closed when the set is done."""
    from tqdm import tqdm

    bars: dict = {}

    def update(name, t, horizon, change):
        bar = bars.get(name)
        if bar is None:
            bar = bars[name] = tqdm(total=round(horizon, 2), desc=f"solving {name} set", unit="s", file=sys.stderr)
        bar.update(round(t - bar.n, 2))
        if t >= horizon - 1e-9:
            bar.close()

    return update
