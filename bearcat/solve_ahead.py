"""Solve a scenario's game before its trials or peers start.

The ground station's guidance needs the game's winning sets; solved here,
with progress bars, they are in the cache before the first trial or peer
asks, so no game waits on a solve and a cache directory that refuses the
write is named before anything else runs.
"""

from __future__ import annotations

from bearcat.progress import solve_bars
from bearcat.writing import writing


def solve_ahead(scenario, netem: str) -> None:
    """Build the ground station of ``scenario`` under profile ``netem`` once,
    which solves (or loads) and caches what its guidance answers from."""
    from bearcat.agents.ground_station.ctf_cache import cache_root
    from bearcat.netem.profiles import load_profile
    from bearcat.scenarios.cast import build_cast

    progress = solve_bars()
    try:
        with writing(cache_root(), "cache directory"):
            build_cast(scenario, load_profile(netem), scenario.seed, people=[], ground=True, ctf_progress=progress)
    finally:
        progress.close()
