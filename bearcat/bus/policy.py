"""Who may publish what, and read what: the bus's access policy, defined once.

Every peer checks the first half on every message it takes (a sealed
message from a peer the policy does not let publish on that key is
refused, whoever vouches for the sender); a ``--secure`` router enforces
both halves, by common name, before anything reaches a peer
(``bus.access``).

=================  =================================  =========================================
role               publishes                          reads
=================  =================================  =========================================
ground-station     guidance, state, uav tasks,        every fix, truth, detection, control,
                   the map, scenario and fault plan   state; every peer's liveliness
launcher           control, fault notices             everything (it records the game)
walker NAME        fix/NAME, truth/NAME (simulated),  guidance/NAME, state, control, faults
                   log/NAME (handed in)
phone NAME         fix/NAME, log/NAME                 guidance/NAME, state, control, faults
uav NAME           fix/NAME, truth/NAME (emulated),   uav/NAME/task, state, control, faults,
                   uav/NAME/detection, log/NAME       every truth (its emulated camera),
                                                      every peer's liveliness
=================  =================================  =========================================

Only the simulator's own bodies (walkers, emulated UAVs) publish truth; a
real phone has none.
"""

from __future__ import annotations

from bearcat.bus import keys
from bearcat.bus.errors import BusError

# Kinds of key each role may publish on; "own" kinds only under its own name.
_ANY = {
    "ground-station": frozenset({"guidance", "state", "uav-task", "map", "scenario", "plan"}),
    "launcher": frozenset({"control", "fault"}),
}
_OWN = {
    "walker": frozenset({"fix", "truth", "log"}),
    "phone": frozenset({"fix", "log"}),
    "uav": frozenset({"fix", "truth", "detection", "log"}),
}


def may_publish(role: str, name: str, key: str) -> bool:
    """Whether peer ``name`` in ``role`` may publish on ``key``."""
    try:
        parsed = keys.parse(key)
    except BusError:
        return False
    if parsed.kind in _ANY.get(role, ()):
        return True
    return parsed.kind in _OWN.get(role, ()) and parsed.agent == name


def publishes(role: str, name: str, game: str) -> list[str]:
    """The keys (and key expressions) ``name`` in ``role`` publishes on in ``game``."""
    out = [keys.every(game, kind) for kind in sorted(_ANY.get(role, ()))]
    for kind in sorted(_OWN.get(role, ())):
        out.append(_own(game, kind, name))
    return out


def reads(role: str, name: str, game: str) -> list[str]:
    """The keys (and key expressions) ``name`` in ``role`` may subscribe to in ``game``."""
    common = [keys.state(game), keys.control(game), keys.fault(game)]
    if role == "launcher":
        return [keys.game_wide(game)]
    if role == "ground-station":
        kinds = ("fix", "truth", "detection")
        return [*(keys.every(game, k) for k in kinds), *common]
    if role in ("walker", "phone"):
        return [keys.guidance(game, name), *common]
    if role == "uav":
        return [keys.uav_task(game, name), keys.every(game, "truth"), *common]
    raise BusError(f"role {role!r} has no access policy")


def watches(role: str, name: str, game: str) -> list[str]:
    """The liveliness key expressions ``name`` in ``role`` may watch in ``game``."""
    if role in ("launcher", "ground-station", "uav"):
        return [keys.every(game, "alive")]
    return [keys.alive(game, "ground-station", keys.GROUND)]


def _own(game: str, kind: str, name: str) -> str:
    if kind == "fix":
        return keys.fix(game, name)
    if kind == "truth":
        return keys.truth(game, name)
    if kind == "detection":
        return keys.detection(game, name)
    if kind == "log":
        return keys.log_query(game, name)
    raise BusError(f"no key of kind {kind!r} belongs to one peer")
