"""A scenario's sets solved before its games, as the commands show it: with
progress bars, and a cache directory that refuses the write named in one
sentence (``runtime.solve_ahead`` does the work)."""

from __future__ import annotations

from collections.abc import Callable

from bearcat.cli.progress import solve_bars
from bearcat.cli.writing import writing


def presolve(scenario, netem: str, *, provisional: bool = False) -> None:
    """``solve_ahead`` with a bar per set solved."""
    from bearcat.agents.cache import cache_root
    from bearcat.runtime.solve_ahead import solve_ahead

    bars = solve_bars()
    try:
        with writing(cache_root(), "cache directory"):
            solve_ahead(scenario, netem, provisional=provisional, progress=bars)
    finally:
        bars.close()


def await_behind(behind, say: Callable[[str], None]) -> bool:
    """``SolveBehind.finish`` with a bar of the game time solved."""
    bars = solve_bars()
    try:
        return behind.finish(say, bars)
    finally:
        bars.close()
