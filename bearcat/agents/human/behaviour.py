"""What a behaviour is: how a simulated person decides where to walk.

A behaviour reads what a person in the field knows: their own position
(people know where they stand), the phase of the game, the phone's
``Screen`` (opponents as last reported, with the reports' ages; the
opponent's winning region; the heading ring; go / no-go) and the
``Situation`` (who they are, their team, the opponents, the regions the
rules name). It answers a direction (east, north; its length does not
matter) or None to stand still.

The built-ins (``behaviours``) and a user's own are entries of one
registry, ``BEHAVIOURS``; a scenario's ``behaviour`` key names one, and its
``options`` table is read into the entry's options type.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from bearcat.agents import options as opts
from bearcat.agents.human.phone import Screen
from bearcat.agents.navigation import Navigator
from bearcat.agents.registry import Registry

TAKES_KEYS = "keys"
"""Trait: the behaviour takes key presses (``press``), so its peer is started in a terminal by a person."""
COMMITS = "commits"
"""Trait: the behaviour commits to its run at some moment for good, and
says when in ``committed_at``: the go of the go/no-go and fake-out studies,
and the ``AGENT.goes`` event fault plans start on."""
TELLS = "events"
"""Trait: the behaviour appends what it wants in the event log to its ``events`` list (one phrase each)."""


@dataclass(frozen=True)
class Situation:
    """What a behaviour may know besides its screen: who it is, its team and
    opponents, and the regions the rules name (shapely, map metres)."""

    agent: str
    team: str
    opponents: tuple[str, ...]
    goal: object  # where this agent is heading in the current phase (attackers)
    forbidden: object  # where this agent may not go (defenders: flag and return regions)
    navigator: Navigator


class Behaviour(Protocol):
    """How a person decides where to walk; subclass it to write one's own.

    The class is made once per agent and game as ``cls(options, rng)``:
    ``options`` the agent's ``options`` table read into ``Options``, ``rng``
    a ``numpy.random.Generator`` seeded from the scenario's seed and the
    agent's name, its own. It may keep state between calls.

    ``decide`` is called ten times a second once the game has started. It
    runs as untrusted code: an exception, an answer that is not None nor a
    finite (east, north) pair, or a live call past the agent's ``budget``
    leaves the person standing for that tick, logged and recorded as a
    ``plugin`` event; the game goes on.

    ``traits`` declares what it does beyond deciding: ``"commits"`` (it has
    ``committed_at``, the game time it went for good, None before),
    ``"keys"`` (it has ``press(key) -> bool``), ``"events"`` (it has an
    ``events`` list of phrases it appends to, each recorded as it appears).
    """

    Options: ClassVar[type[opts.Options]] = opts.NoOptions
    traits: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, options: Any, rng: np.random.Generator) -> None:
        """Keeps nothing: a behaviour with options or randomness takes what it needs."""

    def decide(self, now: float, me: np.ndarray, screen: Screen, situation: Situation) -> Any:
        """The direction to walk now (east, north), or None to stand still."""
        ...


class Commits(Protocol):
    """A behaviour with the ``commits`` trait."""

    committed_at: float | None


class TakesKeys(Protocol):
    """A behaviour with the ``keys`` trait."""

    def press(self, key: str) -> bool:
        """Take a key name (``up``, ``w``, ``space``, ...); False for keys it ignores."""
        ...


class Tells(Protocol):
    """A behaviour with the ``events`` trait."""

    events: list[str]


BEHAVIOURS: Registry[Behaviour] = Registry(
    kind="behaviour",
    plural="behaviours",
    group="bearcat.behaviours",
    protocol=Behaviour,
    builtins="bearcat.agents.human.behaviours",
    traits=frozenset({TAKES_KEYS, COMMITS, TELLS}),
)


def direction_problem(answer: Any) -> str | None:
    """What is wrong with ``answer`` as a decision, None if nothing."""
    if answer is None:
        return None
    try:
        d = np.asarray(answer, dtype=float)
    except (TypeError, ValueError):
        return f"returned {_shown(answer)}, not a direction (east, north) or None"
    if d.shape != (2,):
        return f"returned {_shown(answer)}, not a direction (east, north) or None"
    if not (math.isfinite(d[0]) and math.isfinite(d[1])):
        return f"returned the direction {_shown(answer)}, which is not finite"
    return None


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
