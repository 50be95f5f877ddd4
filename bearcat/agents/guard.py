"""Calls into a plug-in, which is untrusted code in a peer that must not die.

A plug-in that raises, answers something its protocol does not allow, or
takes longer than its budget has failed for that call: the guard gives the
caller its fallback (the agent stands still, the phone shows no advice),
counts the fault, logs one sentence naming the plug-in and what it did (the
first of each kind for each agent, then every hundredth), and keeps a
``PluginFault`` for the runtime to record as a ``plugin`` event, which the
run checker judges. The game goes on.

The budget is held on the clock the runtime gives: the live one's wall
clock, where a slow answer holds up the peer. Simulation gives none: its
time is virtual, a slow answer delays nothing in the game, and a game must
replay the same for a seed on a busy machine as on an idle one. The first
call is free of the budget, since it may import and compile.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

log = logging.getLogger(__name__)

Fault = Literal["raised", "returned", "overran"]
LOGGED_EVERY = 100  # after the first fault of a kind, every hundredth is logged


@dataclass(frozen=True)
class PluginFault:
    """What ``plugin`` did wrong for ``agent`` at game time ``t``: it
    ``raised``, ``returned`` what its protocol does not allow, or
    ``overran`` its budget; ``detail`` says how."""

    t: float
    agent: str
    plugin: str
    fault: Fault
    detail: str

    def sentence(self) -> str:
        return f"{self.agent}: plug-in {self.plugin} {self.detail}"


class Guard:
    """Calls ``plugin``'s methods for ``agent``, each within ``budget``
    seconds of ``clock`` (None: no budget)."""

    def __init__(
        self, agent: str, plugin: str, budget: float | None = None, clock: Callable[[], float] | None = None
    ) -> None:
        self.agent = agent
        self.plugin = plugin
        self.budget = budget
        self.clock = clock
        self.counts: Counter[Fault] = Counter()
        self.faults: list[PluginFault] = []  # every fault, in order; a runtime records those it has not yet
        self._timed = 0  # timed calls so far

    def call(
        self,
        now: float,
        method: Callable[..., Any],
        *args,
        check: Callable[[Any], str | None],
        fallback=None,
        timed: bool = True,
    ):
        """``method(*args)``, or ``fallback`` if it raised, ``check`` found a
        problem with its answer (a phrase such as ``returned a heading of
        1e9 degrees``), or it ran past the budget. A call made once before
        the game (``timed`` False: making the plug-in) is held to no
        budget, and neither is the first timed one."""
        clock = self.clock if timed and self.budget is not None and self._timed > 0 else None
        self._timed += timed
        began = clock() if clock is not None else 0.0
        try:
            answer = method(*args)
        except Exception as exc:
            text = str(exc).splitlines()[0][:200] if str(exc) else ""
            self._fault(now, "raised", f"raised {type(exc).__name__}" + (f": {text}" if text else ""))
            return fallback
        if clock is not None and self.budget is not None:
            took = clock() - began
            if took > self.budget:
                self._fault(now, "overran", f"took {took * 1e3:.0f} ms, past its budget of {self.budget * 1e3:.0f} ms")
                return fallback
        problem = check(answer)
        if problem is not None:
            self._fault(now, "returned", problem)
            return fallback
        return answer

    def _fault(self, now: float, fault: Fault, detail: str) -> None:
        self.counts[fault] += 1
        found = PluginFault(now, self.agent, self.plugin, fault, detail)
        self.faults.append(found)
        n = self.counts[fault]
        if n == 1 or n % LOGGED_EVERY == 0:
            log.warning("%s (%d time%s so far); the call is ignored", found.sentence(), n, "" if n == 1 else "s")
