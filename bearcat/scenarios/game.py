"""What a game is: its teams, its rules, its referee, its guidance and the
people who play it, from a scenario.

A scenario's ``game`` key names an entry of ``GAMES``: the built-ins
(capture-the-flag, open-loop reach-avoid, cooperative pursuit, in
``cast``) or a game of one's own, found as any plug-in is. The entry's
options type is the game's rules: the scenario's ``[rules]`` table is read
into it. Its class declares the two teams that play, the forms of answer
its guidance's advisor gives (which guidance methods build on) and the
method a scenario that names none gets.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import msgspec

from bearcat.agents.registry import Registry

if TYPE_CHECKING:
    from bearcat.agents.ground_station.guidance.service import GuidanceService
    from bearcat.agents.ground_station.referee import Referee
    from bearcat.agents.human.agent import HumanAgent
    from bearcat.netem.profiles import Profile


class Game(Protocol):
    """A game as a scenario sets it up; subclass it to write one's own.

    Made as ``cls(scenario, provisional=..., seed=..., clock=...)`` by every
    peer that plays a part of it: the ground station asks it for the
    ``referee`` and the ``guidance`` service, a walker's peer for its
    ``person``. ``awaited`` names the sets the guidance answers from
    provisional ones until they are solved (None: none)."""

    Options: ClassVar[type[msgspec.Struct]]
    traits: ClassVar[frozenset[str]] = frozenset()
    teams: ClassVar[tuple[str, str]]
    answers: ClassVar[frozenset[str]] = frozenset({"plain"})
    default_guidance: ClassVar[str] = "none"
    awaited: Any = None

    def referee(self, on_truth: bool = True) -> Referee:
        """The referee, judging on the truth (simulation) or on the fixes (real players)."""
        ...

    def guidance(self, profile: Profile, progress=None) -> GuidanceService:
        """The guidance service of the game's aided agents on network ``profile``."""
        ...

    def person(self, spec, profile: Profile, seed: int, clock=None) -> HumanAgent:
        """The person the agent table ``spec`` describes, its behaviour held to its budget on ``clock``."""
        ...


GAMES: Registry[Game] = Registry(
    kind="game",
    plural="games",
    group="bearcat.games",
    protocol=Game,
    builtins="bearcat.scenarios.cast",
)
