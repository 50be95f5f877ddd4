"""A peer restarted mid-game takes up where its last self left off.

What each agent needs is what it last sent: a walker its last true
position (a person does not go back to the start when the phone's app
restarts), the referee its last state (the phase, the game clock, who holds
the flag, who was caught), the guidance the fixes it last showed. The simulated injector finds those in the run's
event log as it is being written; a live peer restarted with ``--resume``
reads them from its own log in the run directory, and what its own log
keeps no body of (a ground station's guidance) from the launcher's.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import msgspec

from bearcat.agents.ground_station.event_log import read_events
from bearcat.agents.ground_station.guidance.service import GuidanceService
from bearcat.bus import keys
from bearcat.bus.errors import BusError
from bearcat.bus.messages import AnyMessage, GameState, Guidance, Message, Truth


def resume(agent, last: Mapping[str, Message], game: str) -> None:
    """Hand ``agent`` what was last sent on its keys (``last``: key -> message), if it takes any."""
    if hasattr(agent, "walker"):
        truth = last.get(keys.truth(game, agent.name))
        if isinstance(truth, Truth):
            agent.resume(truth)
    elif isinstance(agent, GuidanceService):
        agent.resume(m for m in last.values() if isinstance(m, Guidance))
    elif hasattr(agent, "resume"):
        state = last.get(keys.state(game))
        if isinstance(state, GameState):
            agent.resume(state)


def last_sent(
    path: str | Path, *, sender: str | None = None, kinds: tuple[str, ...] | None = None
) -> dict[str, Message]:
    """The latest message sent on each key, from an event log at ``path``
    (empty if there is none): a peer's own, or the launcher's run-wide one,
    which holds what each peer's own log keeps no body of (``live.BODILESS``);
    only what ``sender`` sent, and only on the ``kinds`` of key, if given.
    A line without its message is passed over."""
    path = Path(path)
    if not path.exists():
        return {}
    found: dict[str, Message] = {}
    for event in read_events(path):
        if event.get("event") != "sent" or (sender is not None and event.get("sender") != sender):
            continue
        try:
            if kinds is not None and keys.parse(event["key"]).kind not in kinds:
                continue
            found[event["key"]] = msgspec.convert(event["message"], AnyMessage)
        except (msgspec.ValidationError, KeyError, BusError):
            continue
    return found
