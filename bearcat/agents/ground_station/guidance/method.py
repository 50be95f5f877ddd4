"""What a guidance method is: what the ground station tells one aided phone.

A game's advisor (``ctf``, ``open_loop``, ``pursuit``, ``search``) knows
its solver and the forms of answer it offers: at the positions as
reported (``plain``), against every place the disks round the fixes allow
(``worst_case``), where the trackers predict the players now
(``calibrated``). A guidance method decides, for one aided agent at one
moment, what that agent's phone is told, from a ``GuidanceView``: the
latest fixes as the agent's side knows them, the trackers' beliefs where
the method declares ``TRACKS``, and the advisor's forms to build on.

The built-ins (``methods``) are the three ways bearcat treats stale, noisy
fixes: ``none`` (the thesis's guidance), ``worst-case`` and
``calibrated``. A user's own is an entry of the same registry,
``GUIDANCE_METHODS``, named by ``[guidance] method`` or an agent's own
``guidance`` key, with its options.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import msgspec
import numpy as np

from bearcat.agents import options as opts
from bearcat.agents.ground_station.guidance.fixes import LatestFixes
from bearcat.agents.ground_station.tracker import Belief
from bearcat.agents.registry import Registry
from bearcat.bus.messages import Heading, Lines, Name, Text, check_shown
from bearcat.maps import Map


class Advice(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """What one aided phone is told: the fields of its ``Guidance`` a method
    fills (``bus.messages.Guidance`` says what each means). ``heading`` is
    degrees clockwise from north, the direction to go at full speed; ``go``
    the go / no-go verdict; ``region`` the opponent's winning region as
    ``[lon, lat]`` rings and ``region_of`` whose it is; ``value`` the
    solver's value; ``margin`` what a go added to it; ``note`` a line for
    the screen. The default, every field empty, shows no advice."""

    heading: Heading | None = None
    go: bool | None = None
    region: Lines = []
    region_of: Name | None = None
    value: float | None = None
    margin: float | None = None
    boundary: Lines = []
    possible: Lines = []
    worst_case: bool = False
    uncertain: bool = False
    note: Text = ""

    @classmethod
    def of(cls, fields: dict) -> Advice:
        """The advice an advisor's ``fields`` give (its ``game`` is the service's to say)."""
        return cls(**{k: v for k, v in fields.items() if k != "game"})


NO_ADVICE = Advice(note="no advice")
"""What a phone shows for a moment its method failed."""


@dataclass(frozen=True)
class GuidanceView:
    """What the ground station knows when it answers for ``agent`` at ``now``.

    ``fixes`` holds each agent's latest fix as ``agent``'s side knows it
    (all of them, in a game of full visibility); ``answers`` is the game's
    advisor, whose forms a method may build on, each an ``Advice`` for
    the view: ``answers.plain(view)`` in every game, and where the game
    gives them (its class's ``answers``), ``answers.worst_case(view)`` and
    ``answers.calibrated(view)``; ``teams`` every person's team and
    ``speeds`` every agent's top speed (m/s)."""

    agent: str
    now: float
    map: Map
    fixes: LatestFixes
    answers: Any
    teams: dict[str, str]
    speeds: dict[str, float]

    @property
    def team(self) -> str:
        """The team of the agent answered."""
        return self.teams[self.agent]

    @property
    def opponents(self) -> list[str]:
        """The people of the other team."""
        return [who for who, team in self.teams.items() if team != self.team]

    def position(self, who: str) -> np.ndarray | None:
        """``who``'s last reported position (east, north, map metres); None before its first fix."""
        held = self.fixes.latest.get(who)
        return None if held is None else held[0]

    def age(self, who: str) -> float | None:
        """Seconds since ``who``'s last reported fix was taken; None before its first."""
        held = self.fixes.latest.get(who)
        return None if held is None else self.now - held[1]

    def belief(self, who: str) -> Belief | None:
        """Where ``who``'s tracker believes it is now (position, velocity,
        covariance); None for a method without ``TRACKS`` or before its first fix."""
        return self.fixes.beliefs(self.now).get(who)


class GuidanceMethod(Protocol):
    """What an aided phone is told; subclass it to write one's own.

    Made once per game and aided agent as ``cls(options, rng)``, like a
    ``Behaviour``; ``advise(view)`` answers each time that agent's
    guidance goes out (on each of its fixes, and at the scenario's
    guidance rate) with an ``Advice``. ``needs`` names the forms of the
    game's advisor it builds on (``view.answers``): a scenario whose game
    does not give them all is refused. It runs as untrusted code: an
    exception, an answer that is not an ``Advice`` the wire carries (a
    heading outside [0, 360), a NaN value), or a live answer past its
    budget shows "no advice" on that phone for that moment, logged and
    recorded as a ``plugin`` event.
    """

    Options: ClassVar[type[opts.Options]] = opts.NoOptions
    traits: ClassVar[frozenset[str]] = frozenset()
    needs: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, options: Any, rng: np.random.Generator) -> None:
        """Keeps nothing: a method with options or randomness takes what it needs."""

    def advise(self, view: GuidanceView) -> Advice:
        """What ``view.agent``'s phone is told now."""
        ...


TRACKS = "tracks"
"""Trait: the method reads the trackers' beliefs (``view.belief``), so the ground station keeps a tracker per agent."""

GUIDANCE_METHODS: Registry[GuidanceMethod] = Registry(
    kind="guidance method",
    plural="guidance methods",
    group="bearcat.guidance",
    protocol=GuidanceMethod,
    builtins="bearcat.agents.ground_station.guidance.methods",
    traits=frozenset({TRACKS}),
)


def advice_problem(advice: Any) -> str | None:
    """What is wrong with a method's answer, as a phrase naming it; None if nothing."""
    if not isinstance(advice, Advice):
        text = repr(advice)
        return f"returned {text if len(text) <= 60 else text[:57] + '...'}, not an Advice"
    if advice.heading is not None and not (
        isinstance(advice.heading, float | int) and math.isfinite(advice.heading) and 0.0 <= advice.heading < 360.0
    ):
        return f"returned a heading of {advice.heading!r} degrees, not one in [0, 360)"
    try:
        msgspec.convert(msgspec.structs.asdict(advice), Advice)
        check_shown(advice)
    except (msgspec.ValidationError, ValueError) as exc:
        return f"returned advice the wire cannot carry: {str(exc)[:150]}"
    return None
