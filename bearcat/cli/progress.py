"""The progress bars every command draws, on stderr so stdout stays the command's output.

Two kinds: ``solve_bars`` for the sets a command solves (capture-the-flag
or maneuver sets, in seconds of their horizon, one bar per set), and
``counting`` for a batch of games or trials.

A terminal redraws a bar in place, ten times a second at most; a log file
(stderr not a terminal, as under ``nohup`` or a batch scheduler) gets a
redraw every ``LOGGED_EVERY`` seconds, so that an hour's solve leaves a
few hundred lines of it, not one per solver step.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

LOGGED_EVERY = 10.0  # s between redraws when stderr is not a terminal


def _redraw_every() -> float:
    return 0.1 if sys.stderr.isatty() else LOGGED_EVERY


def solve_bars(
    label: Callable[[str], str] | None = None, change_unit: str = "m", clock: str = "game time"
) -> SolveBars:
    """A ``progress(name, t, horizon, change)`` callback, as the solvers call
    it, that draws one bar per set being solved. ``label(name)`` names a set
    on its bar (by default the capture-the-flag sets' names). A set's bar
    closes when the next set starts or at its horizon; ``progress.close()``
    closes the bar of a set that converged before its horizon."""
    if label is None:
        from bearcat.solvers.ctf.sets import SET_NAMES

        def label(name: str) -> str:
            return f"solving {SET_NAMES[name]} ({name} set)"

    return SolveBars(label, change_unit, clock)


class SolveBars:
    """The callback ``solve_bars`` makes: one bar per set, by its name."""

    def __init__(self, label: Callable[[str], str], change_unit: str, clock: str) -> None:
        from tqdm import tqdm

        self._tqdm = tqdm
        self.label, self.change_unit, self.clock = label, change_unit, clock
        self.bars: dict[str, tqdm] = {}

    def __call__(self, name: str, t: float, horizon: float, change: float) -> None:
        bar = self.bars.get(name)
        if bar is None:
            self.close()
            bar = self.bars[name] = self._tqdm(
                total=round(horizon, 2),
                desc=self.label(name),
                file=sys.stderr,
                mininterval=_redraw_every(),
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.2f}/{total:.2f} s of " + self.clock + " "
                "[{elapsed}<{remaining}{postfix}]",
            )
        bar.set_postfix_str(f"change {change:.3g} {self.change_unit}", refresh=False)
        bar.update(round(t - bar.n, 2))
        if t >= horizon - 1e-9:
            bar.close()

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()


@contextmanager
def counting(total: int, what: str, unit: str) -> Iterator[Callable[..., None]]:
    """A bar over ``total`` tasks; the block calls what it yields once per
    finished task (with any arguments, so it fits as a result callback)."""
    from tqdm import tqdm

    with tqdm(total=total, desc=what, unit=unit, file=sys.stderr, mininterval=_redraw_every()) as bar:

        def finished(*_: object) -> None:
            bar.update(1)

        yield finished
