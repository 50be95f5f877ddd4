"""The options a plug-in reads from its scenario table, and the field types
they are built of.

A plug-in's options are a frozen msgspec Struct subclassing ``Options``:
every key with its type, bounds and default, so a scenario that gives a
wrong key or value is refused in a sentence naming it
(``agent[0].options.spread: must be a number in [0, 180] degrees, got 400``).
The annotated types below carry their bounds and units for that sentence;
a plug-in's own options use them as the built-ins' do.
"""

from __future__ import annotations

from typing import Annotated

import msgspec
from msgspec import Meta

Coordinate = Annotated[float, Meta(ge=-1e7, le=1e7, extra={"unit": "m"})]
Point = Annotated[tuple[Coordinate, Coordinate], Meta(description="[east, north] in metres")]
Route = Annotated[tuple[Point, ...], Meta(min_length=1, description="a list of [east, north] points in metres")]
Distance = Annotated[float, Meta(ge=0.0, le=1000.0, extra={"unit": "m"})]
Share = Annotated[float, Meta(ge=0.0, le=1.0)]
Angle = Annotated[float, Meta(ge=0.0, le=180.0, extra={"unit": "degrees"})]
Lag = Annotated[float, Meta(ge=0.0, le=60.0, extra={"unit": "s"})]
Period = Annotated[float, Meta(gt=0.0, le=3600.0, extra={"unit": "s"})]
Memory = Annotated[float, Meta(ge=0.0, le=3600.0, extra={"unit": "s"})]


class Options(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """A plug-in's options: its keys are exactly the fields."""

    def places(self) -> tuple[tuple[str, tuple[float, float]], ...]:
        """(key, point) of every point these options send the agent to, each
        checked to lie in the map's free space when the scenario is read."""
        return ()


class NoOptions(Options, frozen=True):
    """The options of a plug-in that takes none."""
