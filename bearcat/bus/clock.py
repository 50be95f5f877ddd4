"""Clocks: virtual time in simulation, the wall clock in live runs.

Agents never read a clock themselves; the runtime passes ``now`` into
``handle`` and ``tick``. The runtimes and the recorder read one of these.
"""

from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    def now(self) -> float:
        """Seconds: game time in simulation, Unix time in live runs."""


class WallClock:
    """Unix time, comparable between processes and machines (as far as their clocks agree)."""

    def now(self) -> float:
        return time.time()


class VirtualClock:
    """The time of a discrete-event environment (anything with ``now``, such as simpy's)."""

    def __init__(self, environment) -> None:
        self._environment = environment

    def now(self) -> float:
        return float(self._environment.now)
