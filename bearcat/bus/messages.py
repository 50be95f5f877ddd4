"""The typed messages of the bus, one schema version for all.

Positions on the wire are WGS84 degrees (what phones and PX4 report),
headings degrees clockwise from north in ``[0, 360)``, times seconds on the
sender's clock (virtual in simulation, Unix time in live runs). Every field
carries its range, so decoding rejects out-of-range, NaN and infinite
numbers, unknown fields and oversized lists before any agent sees them.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import msgspec

from bearcat.bus.keys import NAME_PATTERN

SCHEMA_VERSION = 1

Name = Annotated[str, msgspec.Meta(pattern=NAME_PATTERN, description="1 to 64 letters, digits, '-' or '_'")]
Latitude = Annotated[float, msgspec.Meta(ge=-90.0, le=90.0)]
Longitude = Annotated[float, msgspec.Meta(ge=-180.0, le=180.0)]
Heading = Annotated[float, msgspec.Meta(ge=0.0, lt=360.0)]
HalfTurn = Annotated[float, msgspec.Meta(ge=0.0, lt=180.0)]
Time = Annotated[float, msgspec.Meta(ge=0.0, le=1e12)]
Metres = Annotated[float, msgspec.Meta(ge=0.0, le=1e7)]
Altitude = Annotated[float, msgspec.Meta(ge=-1e4, le=1e5)]
Speed = Annotated[float, msgspec.Meta(ge=0.0, le=1e3)]
Sequence = Annotated[int, msgspec.Meta(ge=0, le=2**63 - 1)]
# GeoJSON's order, as the maps use: longitude first.
Point = tuple[Longitude, Latitude]
OUTLINE_LINES = 64
OUTLINE_POINTS = 4096
"""An outline (a region, a set of lines) is up to ``OUTLINE_LINES`` closed rings
or open lines of ``OUTLINE_POINTS`` points in all: more than a phone's screen
can show, and few enough that the largest guidance stays a fraction of a
megabyte on a cellular link."""
Line = Annotated[list[Point], msgspec.Meta(max_length=OUTLINE_POINTS)]
Lines = Annotated[list[Line], msgspec.Meta(max_length=OUTLINE_LINES)]
Text = Annotated[str, msgspec.Meta(max_length=200)]
Phase = Literal["waiting", "running", "paused", "ended"]
"""Where a game is: the referee's phases."""


class Message(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True, tag_field="type"):
    """Base of every message: ``v`` is the schema version; other versions are refused."""

    v: int = SCHEMA_VERSION

    def __post_init__(self):
        if self.v != SCHEMA_VERSION:
            raise ValueError(f"schema version {self.v} is not the supported {SCHEMA_VERSION}")


class Fix(Message, tag="fix", frozen=True):
    """A position report from an agent's phone GPS or a UAV's telemetry.
    ``accuracy`` is the reported horizontal error (metres, 1 sigma); ``heading``
    the compass; ``seq`` counts the sender's fixes, so a receiver can tell a
    lost fix from a late one."""

    agent: Name
    seq: Sequence
    t: Time
    lat: Latitude
    lon: Longitude
    alt: Altitude | None = None
    heading: Heading | None = None
    accuracy: Metres | None = None


class Truth(Message, tag="truth", frozen=True):
    """Where an agent really is (simulation only; for the referee and the
    recorder); ``going``, that its behaviour has committed to its run (a
    fake-out's go, a go-no-go's go), which faults may count from."""

    agent: Name
    t: Time
    lat: Latitude
    lon: Longitude
    alt: Altitude | None = None
    heading: Heading | None = None
    going: bool = False


class Report(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """An agent as the guidance saw it: its last delivered fix and that fix's
    time; ``radius`` (metres) bounds where it may be by the guidance's time,
    its top speed times the fix's age plus the fix's 95 % error (None where
    the ground station does not know its top speed). Where calibrated
    guidance tracks the agent, ``predicted`` is where the tracker believes
    it is at the guidance's time (``[lon, lat]``) and ``ellipse`` that
    belief's 95 % ellipse: semi-major and semi-minor axes in metres and the
    major axis's bearing in degrees clockwise from north, in [0, 180)."""

    agent: Name
    t: Time
    lat: Latitude
    lon: Longitude
    radius: Metres | None = None
    predicted: Point | None = None
    ellipse: tuple[Metres, Metres, HalfTurn] | None = None


class Guidance(Message, tag="guidance", frozen=True):
    """What one agent's screen shows, computed from the fixes the network delivered.

    ``game`` names the advisor behind it (``ctf``, ``reach-avoid``,
    ``pursuit``, ``search``, or a game of one's own's; ``none``: positions
    only); ``heading`` is the recommended
    direction at full speed (None: no recommendation); ``region`` the
    opponent's winning region as polygons (exterior rings) and ``region_of``
    whose region it is; ``go`` the go / no-go verdict where the game has
    one; ``value`` the solver's value at the current state (time to win, area
    of the safe set, ...); ``boundary`` open lines to show (a pursuer's active
    boundary, a planned path); ``reports`` every agent as last reported (in a
    game of limited visibility, as last seen by the agent's side);
    ``possible`` where an unseen opponent may be (P_D of thesis 6.2), and
    ``worst_case`` whether ``value``, ``heading`` and ``go`` hold against
    every one of those places; ``uncertain`` that the answer, robust to where
    the players may be (each report's ``radius``), differs from the one the
    positions as reported would give; ``seen_by`` the opponents' UAVs that
    have just seen this agent. With calibrated guidance, ``margin`` (metres)
    is what the attacker's ``go`` added to ``value`` before it said go:
    the measured quantile of the value's error at the reports' age, so that
    a go is wrong at most as often as the scenario allows.

    Every point of ``region``, ``boundary`` and ``possible`` is a WGS84
    ``[lon, lat]`` pair, GeoJSON's order (RFC 7946), as in the maps: a ring
    or line reads as a GeoJSON ``LinearRing`` or ``LineString``."""

    agent: Name
    seq: Sequence
    t: Time
    game: Name
    heading: Heading | None = None
    region: Lines = []
    region_of: Name | None = None
    go: bool | None = None
    value: float | None = None
    boundary: Lines = []
    reports: Annotated[list[Report], msgspec.Meta(max_length=64)] = []
    possible: Lines = []
    worst_case: bool = False
    uncertain: bool = False
    margin: float | None = None
    seen_by: Annotated[list[Name], msgspec.Meta(max_length=64)] = []
    note: Text = ""

    def __post_init__(self):
        super().__post_init__()
        check_shown(self)


def check_shown(shown) -> None:
    """Raise ValueError for what a screen cannot show of ``shown`` (a
    ``Guidance``, or the advice that fills one): a value or margin that is
    not finite, or outlines of more than ``OUTLINE_POINTS`` points."""
    for name in ("value", "margin"):
        number = getattr(shown, name)
        if number is not None and not math.isfinite(number):
            raise ValueError(f"{name} must be finite")
    for name in ("region", "boundary", "possible"):
        points = sum(len(line) for line in getattr(shown, name))
        if points > OUTLINE_POINTS:
            raise ValueError(f"{name} has {points} points in all, more than {OUTLINE_POINTS}")


class GameState(Message, tag="state", frozen=True):
    """The referee's view of the game. ``phase`` moves waiting -> running
    (-> paused -> running) -> ended; ``winner`` is a team and ``reason`` says why."""

    seq: Sequence
    t: Time
    phase: Phase
    elapsed: Annotated[float, msgspec.Meta(ge=0.0, le=1e9)] = 0.0
    winner: Name | None = None
    reason: Text = ""
    flag_holder: Name | None = None
    captured: Annotated[list[Name], msgspec.Meta(max_length=64)] = []
    judged_on: Literal["truth", "fixes"] = "truth"


class Control(Message, tag="control", frozen=True):
    """A command to every peer of a game; ``seq`` numbers a launcher's commands."""

    t: Time
    command: Literal["start", "pause", "resume", "stop"]
    reason: Text = ""
    seq: Sequence = 0


class UavTask(Message, tag="uav-task", frozen=True):
    """Where a UAV should go: a search target or a waypoint; land or hold in place."""

    uav: Name
    seq: Sequence
    t: Time
    kind: Literal["search", "waypoint", "hold", "land"]
    lat: Latitude
    lon: Longitude
    alt: Altitude


class Detection(Message, tag="detection", frozen=True):
    """A UAV's camera saw ``agent`` at (``lat``, ``lon``) at time ``t``."""

    uav: Name
    t: Time
    agent: Name
    lat: Latitude
    lon: Longitude


class FaultNotice(Message, tag="fault", frozen=True):
    """Fault ``fault`` of the run's plan holds from ``start`` until ``end``
    (None: until healed or the end), on the launcher's clock: each peer
    applies what concerns it."""

    fault: Annotated[int, msgspec.Meta(ge=0, le=10_000)]
    start: Time
    end: Time | None = None


AnyMessage = Fix | Truth | Guidance | GameState | Control | UavTask | Detection | FaultNotice
MESSAGE_TYPES = (Fix, Truth, Guidance, GameState, Control, UavTask, Detection)
