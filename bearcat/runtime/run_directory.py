"""Run directories: where a run keeps what it recorded, never over another's.

A run directory the user names that already holds something is left as it
is: the run goes to the first free ``NAME-1``, ``NAME-2``, ... beside it,
so a second run never overwrites the first or mixes its files with it.
Each run keeps the scenario it played (``scenario.toml``), so the run
checker judges it from the directory alone.
"""

from __future__ import annotations

from pathlib import Path

SCENARIO = "scenario.toml"


def fresh(path: Path) -> Path:
    """``path`` if it is free (absent, or an empty directory), else the first free ``path-N``."""
    path = Path(path)
    candidate, n = path, 0
    while _taken(candidate):
        n += 1
        candidate = path.with_name(f"{path.name}-{n}")
    return candidate


def write_scenario(directory: Path, scenario) -> None:
    """Keep the scenario a run played beside what it recorded."""
    (Path(directory) / SCENARIO).write_text(scenario.text, encoding="utf-8")


def _taken(path: Path) -> bool:
    if not path.exists():
        return False
    return not path.is_dir() or any(path.iterdir())
