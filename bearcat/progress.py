"""The progress bars every command draws, on stderr so stdout stays the command's output.

Two kinds: ``solve_bars`` for the sets a command solves (capture-the-flag
or maneuver sets, in seconds of their horizon, one bar per set), and
``counting`` for a batch of games or trials.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager


def solve_bars(label: Callable[[str], str] | None = None, change_unit: str = "m", clock: str = "game time"):
    """A ``progress(name, t, horizon, change)`` callback, as the solvers call
    it, that draws one bar per set being solved. ``label(name)`` names a set
    on its bar (by default the capture-the-flag sets' names). A set's bar
    closes when the next set starts or at its horizon; ``progress.close()``
    closes the bar of a set that converged before its horizon."""
    from tqdm import tqdm

    if label is None:
        from bearcat.solvers.ctf import SET_NAMES

        def label(name: str) -> str:
            return f"solving {SET_NAMES[name]} ({name} set)"

    bars: dict = {}

    def update(name: str, t: float, horizon: float, change: float) -> None:
        bar = bars.get(name)
        if bar is None:
            update.close()
            bar = bars[name] = tqdm(
                total=round(horizon, 2),
                desc=label(name),
                file=sys.stderr,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.2f}/{total:.2f} s of " + clock + " "
                "[{elapsed}<{remaining}{postfix}]",
            )
        bar.update(round(t - bar.n, 2))
        bar.set_postfix_str(f"change {change:.3g} {change_unit}")
        if t >= horizon - 1e-9:
            bar.close()

    update.close = lambda: [bar.close() for bar in bars.values()]
    return update


@contextmanager
def counting(total: int, what: str, unit: str) -> Iterator[Callable[..., None]]:
    """A bar over ``total`` tasks; the block calls what it yields once per
    finished task (with any arguments, so it fits as a result callback)."""
    from tqdm import tqdm

    with tqdm(total=total, desc=what, unit=unit, file=sys.stderr) as bar:
        yield lambda *_: bar.update(1)
