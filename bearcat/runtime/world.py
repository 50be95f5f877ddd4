"""The world a game is played in, built once for both runners.

A scenario is played on a network profile, for a seed, over a transport,
under a fault plan, with its dead zones; each of those is the scenario's
own unless the run says otherwise. Simulation and a live peer both start
from this ``World``: its people and ground station (``cast``) and the
shim that impairs what a peer receives (``shim``), so the two runners mean
the same by a scenario and differ only in their clock and transport.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import shapely
from shapely.geometry.base import BaseGeometry

from bearcat.netem.link import LinkModel
from bearcat.netem.profiles import Profile, load_profile
from bearcat.netem.shim import Shim
from bearcat.scenarios.cast import Cast, build_cast
from bearcat.scenarios.schema import Scenario


@dataclass(frozen=True)
class World:
    """``scenario`` on ``profile``, seeded ``seed``, best-effort messages
    over ``transport``, under the fault plan ``plan``; ``zones`` its dead
    zones as one geometry (None: none)."""

    scenario: Scenario
    profile: Profile
    seed: int
    transport: str
    plan: tuple
    zones: BaseGeometry | None

    def cast(self, **parts) -> Cast:
        """The agents of the world (``scenarios.cast.build_cast``'s ``parts``: which people, UAVs, ground)."""
        return build_cast(self.scenario, self.profile, self.seed, **parts)

    def shim(
        self,
        record,
        where: Callable[[str], tuple[float, float] | None],
        colocated: tuple[str, ...],
        *,
        link: LinkModel | None = None,
        epoch: float | None = 0.0,
    ) -> Shim:
        """The shim of a peer that records into ``record`` and finds where
        each peer is with ``where`` (asked only where there are dead zones);
        ``colocated`` peers share the ground station's machine. ``link`` is
        the profile's unless given (a kernel network impairs the packets
        itself); ``epoch`` when outages count from (None: the start command)."""
        return Shim(
            self.profile.link if link is None else link,
            self.seed,
            dead_zones=self.zones,
            where=where if self.zones is not None else None,
            record=record,
            colocated=colocated,
            epoch=epoch,
            transport=self.transport,
            lease=self.scenario.lease,
        )


def world_of(
    scenario: Scenario,
    *,
    seed: int | None = None,
    netem: str | None = None,
    transport: str | None = None,
    plan: tuple | None = None,
) -> World:
    """The world of ``scenario``, with the run's own seed, profile, transport
    and fault plan where given (None: the scenario's)."""
    zones = shapely.union_all([shapely.Polygon(z) for z in scenario.dead_zones]) if scenario.dead_zones else None
    return World(
        scenario=scenario,
        profile=load_profile(netem or scenario.netem),
        seed=scenario.seed if seed is None else int(seed),
        transport=transport or scenario.transport,
        plan=scenario.faults if plan is None else tuple(plan),
        zones=zones,
    )
