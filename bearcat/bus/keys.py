"""The key expressions of the bus, defined once.

::

    bearcat/{game}/fix/{agent}          position report (phone GPS or UAV telemetry)
    bearcat/{game}/guidance/{agent}     guidance for one agent
    bearcat/{game}/state                game state from the referee
    bearcat/{game}/uav/{uav}/task       search target or waypoint for a UAV
    bearcat/{game}/uav/{uav}/detection  an agent the UAV's camera saw
    bearcat/{game}/truth/{agent}        simulation only
    bearcat/{game}/control              start / pause / stop
    bearcat/{game}/fault                a fault of the run's plan begins (fault injection)
    bearcat/{game}/alive/{role}/{agent} liveliness tokens
    bearcat/{game}/map, .../scenario    queryables of the ground station

Names (games, agents, roles) are single key chunks of letters, digits, ``-``
and ``_``: no ``/``, no wildcards, so a name can never widen a subscription.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache

from bearcat.bus.errors import BusError

ROOT = "bearcat"
ROLES = ("walker", "phone", "ground-station", "uav", "referee", "recorder", "launcher")

GROUND = "gs"
"""The ground station's peer name (its referee, guidance and UAV tasking run in it), defined here only."""

NAME_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"
"""Every game, agent and peer name: one key chunk, safe in a file name, 64 characters at most."""
_NAME = re.compile(NAME_PATTERN)

# Kinds of key, with the chunk pattern after "bearcat/{game}/"; "{}" is a name.
_KINDS = {
    "fix": ("fix", "{}"),
    "guidance": ("guidance", "{}"),
    "state": ("state",),
    "uav-task": ("uav", "{}", "task"),
    "detection": ("uav", "{}", "detection"),
    "truth": ("truth", "{}"),
    "control": ("control",),
    "fault": ("fault",),
    "alive": ("alive", "{}", "{}"),
    "map": ("map",),
    "scenario": ("scenario",),
    "plan": ("plan",),
    "log": ("log", "{}"),
}


BEST_EFFORT_KINDS = ("fix", "guidance", "truth")
"""Streams where a newer message replaces an older one: a lost one is lost,
not delivered late in a burst. Every other kind goes reliably."""


def reliable(key: str) -> bool:
    """Whether messages on ``key`` go reliably (game state, control, UAV tasks, detections)."""
    return parse(key).kind not in BEST_EFFORT_KINDS


def check_name(name: str, what: str = "name") -> str:
    """``name`` if it can stand as one key chunk, else a BusError naming it."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise BusError(f"{what} {name!r} must be 1-64 letters, digits, '-' or '_'")
    return name


def _key(game: str, *chunks: str) -> str:
    return "/".join((ROOT, check_name(game, "game"), *chunks))


def fix(game: str, agent: str) -> str:
    return _key(game, "fix", check_name(agent, "agent"))


def guidance(game: str, agent: str) -> str:
    return _key(game, "guidance", check_name(agent, "agent"))


def state(game: str) -> str:
    return _key(game, "state")


def uav_task(game: str, uav: str) -> str:
    return _key(game, "uav", check_name(uav, "uav"), "task")


def detection(game: str, uav: str) -> str:
    return _key(game, "uav", check_name(uav, "uav"), "detection")


def truth(game: str, agent: str) -> str:
    return _key(game, "truth", check_name(agent, "agent"))


def control(game: str) -> str:
    return _key(game, "control")


def fault(game: str) -> str:
    return _key(game, "fault")


def alive(game: str, role: str, agent: str) -> str:
    if role not in ROLES:
        raise BusError(f"role {role!r} is not one of {', '.join(ROLES)}")
    return _key(game, "alive", role, check_name(agent, "agent"))


def map_query(game: str) -> str:
    return _key(game, "map")


def scenario_query(game: str) -> str:
    return _key(game, "scenario")


def plan_query(game: str) -> str:
    """Where the ground station serves the run's fault plan, to peers started on other machines."""
    return _key(game, "plan")


def log_query(game: str, peer: str) -> str:
    """Where a peer started on another machine hands the launcher its log at the end."""
    return _key(game, "log", check_name(peer, "peer"))


def every(game: str, kind: str) -> str:
    """The key expression matching every key of ``kind`` in ``game`` (for
    subscribers: every fix, every peer's liveliness, ...)."""
    if kind not in _KINDS:
        raise BusError(f"there is no key kind {kind!r}; the kinds are {', '.join(_KINDS)}")
    chunks = ["*" if c == "{}" else c for c in _KINDS[kind]]
    return _key(game, *chunks)


def any_game(kind: str) -> str:
    """The key expression matching every key of ``kind`` in every game."""
    if kind not in _KINDS:
        raise BusError(f"there is no key kind {kind!r}; the kinds are {', '.join(_KINDS)}")
    return "/".join((ROOT, "*", *("*" if c == "{}" else c for c in _KINDS[kind])))


KINDS = tuple(_KINDS)


def game_wide(game: str) -> str:
    """Every key of one game (the recorder's subscription)."""
    return _key(game, "**")


@dataclass(frozen=True)
class ParsedKey:
    """What a concrete key names: its ``kind``, the ``game``, and the names it
    carries (``agent`` for fix/guidance/truth/alive, ``uav`` for uav-task and detection,
    ``role`` for alive)."""

    kind: str
    game: str
    agent: str | None = None
    role: str | None = None


@lru_cache(maxsize=4096)
def parse(key: str) -> ParsedKey:
    """The kind and names of a concrete key; a BusError for any other string.
    (A game has a few dozen keys, each parsed on every message: cached.)"""
    chunks = str(key).split("/")
    if len(chunks) < 3 or chunks[0] != ROOT or not _NAME.match(chunks[1]):
        raise BusError(f"key {key!r} is not a bearcat key")
    game, rest = chunks[1], chunks[2:]
    for kind, pattern in _KINDS.items():
        if len(pattern) != len(rest):
            continue
        names = []
        for want, got in zip(pattern, rest):
            if want == "{}":
                if not _NAME.match(got):
                    break
                names.append(got)
            elif want != got:
                break
        else:
            if kind == "alive":
                role, agent = names
                if role not in ROLES:
                    break
                return ParsedKey(kind, game, agent=agent, role=role)
            return ParsedKey(kind, game, agent=names[0] if names else None)
    raise BusError(f"key {key!r} is not a bearcat key")
