"""The guidance service: what each phone shows, from the fixes the network delivered.

For each agent, on each of its new fixes and at least ten times a second
(the scenario's rate), it takes the latest fix of every agent, as the
ground-station laptop of thesis 3.5 did, and sends that agent a
``Guidance``: every agent as last reported, with the disk it may be in by
now (``uncertainty``), and for an aided agent its advisor's
answer at those positions. An unaided agent's phone shows
positions only.

In a game of limited visibility (a ``Sight``), each agent is told only
what its side has seen: its teammates and their UAVs always, an opponent
while the two are in line of sight (both learn of each other at once) or
when one of its side's UAVs detected it; the agent a UAV saw is alerted
(``seen_by``). The advisor then answers from what that agent knows.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from bearcat.agents.ground_station.guidance.fixes import LatestFixes
from bearcat.agents.ground_station.tracker import Trackers
from bearcat.agents.protocol import Send
from bearcat.bus import keys
from bearcat.bus.messages import Detection, Fix, GameState, Guidance, Message
from bearcat.maps import Map

SPOTTED_FOR = 2.0  # s an agent's screen says a UAV saw it


class GuidanceService:
    """Sends each of ``agents`` its guidance: as soon as a new fix of that
    agent arrives (so a phone's answer follows its own fix at once, and no
    faster than its fixes come), and at the scenario's ``rate`` whenever a
    period passed without one (so it also follows the others' moves).
    ``advisor(agent, fixes, now)`` adds the solver's part for an aided agent
    (None: positions only). ``tracking``, where some guidance is
    calibrated, makes the trackers each view of the fixes keeps."""

    role = "ground-station"
    watches: tuple[str, ...] = ()

    def __init__(
        self,
        game: str,
        game_map: Map,
        agents,
        *,
        advisor=None,
        aided=None,
        rate: float = 10.0,
        name: str = keys.GROUND,
        sight=None,
        uncertainty=None,
        tracking: Callable[[], Trackers] | None = None,
    ) -> None:
        self.game, self.name, self.map = game, name, game_map
        self.agents = tuple(agents)
        self.advisor = advisor
        self.aided = dict(aided or {})
        self.uncertainty = uncertainty
        self.period = 1.0 / rate
        self.ended = False
        self.sight = sight
        self.subscriptions: tuple[str, ...] = (keys.every(game, "fix"), keys.state(game))
        if sight is not None:
            self.subscriptions += (keys.every(game, "detection"),)

        def view() -> LatestFixes:
            return LatestFixes(game_map, None if tracking is None else tracking())

        self.fixes = view()
        self.known = {a: view() for a in self.agents} if sight is not None else None
        self.spotted: dict[str, tuple[str, float]] = {}  # agent -> (UAV that saw it, when)
        self.seq = 0
        self._last = {a: -np.inf for a in self.agents}

    def start(self, now: float) -> list[Send]:
        return []

    def warm_up(self, starts) -> None:
        """Have the advisor answer once with the agents at ``starts`` (agent ->
        map point), keeping nothing. A process's first answer loads compiled
        solver and query code from numba's cache (a fifth to a third of a
        second in every game measured) or, after a fresh clone, compiles it
        (two seconds for capture-the-flag); the ground station does this
        before it says it is up, so no fix of the game waits for it."""
        if self.advisor is not None:
            self.advisor.warm_up(starts)

    def handle(self, key: str, message: Message, now: float) -> list[Send]:
        if isinstance(message, Fix):
            if not self.fixes.take(message):
                return []
            if self.known is not None:
                self._share(message, self.known)
            if message.agent in self._last:
                return self._send([message.agent], now)
        elif isinstance(message, Detection) and self.known is not None:
            seen = Fix(agent=message.agent, seq=0, t=message.t, lat=message.lat, lon=message.lon)
            for viewer in self.agents:
                if self.sight.allies(viewer, message.uav):
                    self.known[viewer].take(seen)
            self.spotted[message.agent] = (message.uav, now)
        elif isinstance(message, GameState):
            self.ended = message.phase == "ended"
            if self.advisor is not None:
                self.advisor.state(message)
        return []

    def peer(self, key: str, alive: bool, now: float) -> list[Send]:
        return []

    def resume(self, sent: Iterable[Guidance]) -> None:
        """Take up where the guidance ``sent`` before a restart left off: every
        fix it showed, with the fix's own time (so its age, and the disk the
        agent may be in, go on growing until a newer fix arrives), and its
        count. A restarted ground station does not forget where everyone was."""
        for guidance in sent:
            self.seq = max(self.seq, guidance.seq)
            for report in guidance.reports:
                fix = Fix(agent=report.agent, seq=0, t=report.t, lat=report.lat, lon=report.lon)
                self.fixes.take(fix)
                if self.known is not None and guidance.agent in self.known:
                    self.known[guidance.agent].take(fix)

    def tick(self, now: float) -> list[Send]:
        due = [a for a in self.agents if now - self._last[a] >= self.period - 1e-9]
        return self._send(due, now)

    def _share(self, fix: Fix, known: dict[str, LatestFixes]) -> None:
        """Tell whoever may know of ``fix`` (in ``known``, what each agent knows):
        its side; and, if it is in line of sight of an opponent, that opponent,
        who is seen in turn."""
        sight, mover = self.sight, fix.agent
        where = self.fixes.latest[mover][0]
        for viewer in self.agents:
            if sight.allies(viewer, mover):
                known[viewer].take(fix)
                continue
            held = self.fixes.latest.get(viewer)
            if held is None or mover in sight.uavs or not sight.sees(held[0], where):
                continue
            known[viewer].take(fix)
            if mover in known:
                known[mover].take(held[2])

    def _send(self, agents, now: float) -> list[Send]:
        if self.ended or not agents:
            return []
        everything = self.fixes.reports(now, self.uncertainty) if self.known is None else None
        out = []
        for agent in agents:
            fixes = self.fixes if self.known is None else self.known[agent]
            fields: dict[str, Any] = {"game": "none"}
            if self.advisor is not None and self.aided.get(agent):
                fields = self.advisor(agent, fixes, now)
            spotted = self.spotted.get(agent)
            if spotted is not None and now - spotted[1] <= SPOTTED_FOR:
                fields = {**fields, "seen_by": [spotted[0]]}
            self.seq += 1
            self._last[agent] = now
            reports = everything if everything is not None else fixes.reports(now, self.uncertainty)
            out.append(
                Send(
                    keys.guidance(self.game, agent),
                    Guidance(agent=agent, seq=self.seq, t=now, reports=reports, **fields),
                )
            )
        return out
