"""What a UAV tasking policy is: where the attacking side's UAVs search next.

Once a second the ground station's tasker updates where the unseen
defender may be (``P_D``) and what the attacking side sees, and asks the
scenario's policy for each UAV's next point in turn, each UAV seeing the
ground the ones before it are bound for as already watched, so two UAVs
do not search the same place. The built-ins (``tasking_policies``) are the
thesis's reachability hierarchy and its two baselines; a user's own is an
entry of the same registry, ``TASKING``, named by a UAV's ``search`` key
with its ``search_options``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from bearcat.agents import options as opts
from bearcat.agents.registry import Registry
from bearcat.maps import Map
from bearcat.solvers.grid import Grid


@dataclass(frozen=True)
class Uav:
    """One UAV as the tasker flies it: its name, speed, camera radius r_q and altitude."""

    name: str
    speed: float
    camera_radius: float
    altitude: float


@dataclass(frozen=True)
class SearchView:
    """What the ground station knows when it tasks one UAV, on the search
    grid (boolean masks indexed ``[ix, iy]``, map metres):

    - ``possible``: where the defender may be and no camera, nor a UAV
      tasked before this one, is about to look (``P_D`` less ``V_Q``);
    - ``seen_by_attacker`` and ``seen_by_uavs``: ``V_A`` from the
      attacker's last fix, and ``V_Q`` with the ground the UAVs tasked
      before are bound for;
    - ``attacker`` and ``at``: the attacker's and this UAV's last fixes;
    - ``defender_wins()``: ``W_D(x_a)``, where the defender would win
      against the attacker where it is, from the solved game (computed
      when asked; all False where no game is solved);
    - ``uavs``: every UAV of the side, in the order they are tasked."""

    map: Map
    grid: Grid
    terrain: np.ndarray
    possible: np.ndarray
    seen_by_attacker: np.ndarray
    seen_by_uavs: np.ndarray
    attacker: np.ndarray
    at: np.ndarray
    defender_speed: float
    defender_wins: Callable[[], np.ndarray]
    uavs: tuple[Uav, ...]


class TaskingPolicy(Protocol):
    """Where a UAV searches next; subclass it to write one's own.

    Made once per game as ``cls(options, rng)``, like a ``Behaviour``;
    ``next_point(uav, view)`` answers each second for each UAV the point
    (east, north, map metres) it flies to next and, for the record, the
    tier of the thesis's hierarchy the point came from (None where that
    does not apply), or None for no new point. It runs as untrusted code:
    an exception, a point that is not a finite pair on the map, or a tier
    that is not an integer keeps the UAV on its last task for that second,
    logged and recorded as a ``plugin`` event.
    """

    Options: ClassVar[type[opts.Options]] = opts.NoOptions
    traits: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, options: Any, rng: np.random.Generator) -> None:
        """Keeps nothing: a policy with options or randomness takes what it needs."""

    def next_point(self, uav: Uav, view: SearchView) -> tuple[Any, int | None] | None:
        """The point ``uav`` flies to next, with its tier; None for none."""
        ...


NEEDS_SETS = "needs-sets"
"""Trait: the policy reads ``view.defender_wins()``, so the game's sets must be solved for it."""

TASKING: Registry[TaskingPolicy] = Registry(
    kind="tasking policy",
    plural="tasking policies",
    group="bearcat.tasking",
    protocol=TaskingPolicy,
    builtins="bearcat.agents.ground_station.tasking_policies",
    traits=frozenset({NEEDS_SETS}),
)


def point_problem(game_map: Map) -> Callable[[Any], str | None]:
    """The check of a policy's answer on ``game_map``: what is wrong with it, None if nothing."""
    xmin, ymin, xmax, ymax = game_map.bounds

    def problem(answer: Any) -> str | None:
        if answer is None:
            return None
        if not isinstance(answer, tuple) or len(answer) != 2:
            return f"returned {_shown(answer)}, not (point, tier) or None"
        point, tier = answer
        if point is None:
            return None
        try:
            x, y = (float(v) for v in point)
        except (TypeError, ValueError):
            return f"returned {_shown(answer)}, not (point, tier) or None with the point (east, north)"
        if not (math.isfinite(x) and math.isfinite(y)):
            return f"returned the point {_shown(point)}, which is not finite"
        if not (xmin <= x <= xmax and ymin <= y <= ymax):
            return f"returned the point ({x:g}, {y:g}), off map {game_map.name}"
        if tier is not None and not isinstance(tier, int | np.integer):
            return f"returned the tier {_shown(tier)}, not an integer or None"
        return None

    return problem


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
