"""The guidance service: what each phone shows, from the fixes the network delivered.

For each agent, on each of its new fixes and at least ten times a second
(the scenario's rate), it takes the latest fix of every agent, as the
ground-station laptop of thesis 3.5 did, and sends that agent a
``Guidance``: every agent as last reported, with the disk it may be in by
now (``uncertainty``), and for an aided agent what its guidance method
advises (``method``), held to the method's budget by a guard. An unaided
agent's phone shows positions only.

In a game of limited visibility (a ``Sight``), each agent is told only
what its side has seen: its teammates and their UAVs always, an opponent
while the two are in line of sight (both learn of each other at once) or
when one of its side's UAVs detected it; the agent a UAV saw is alerted
(``seen_by``). The advisor then answers from what that agent knows.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import msgspec
import numpy as np

from bearcat.agents.ground_station.guidance.fixes import LatestFixes
from bearcat.agents.ground_station.guidance.method import (
    NO_ADVICE,
    Advice,
    GuidanceMethod,
    GuidanceView,
    advice_problem,
)
from bearcat.agents.ground_station.tracker import Trackers
from bearcat.agents.guard import Guard, PluginFault
from bearcat.agents.protocol import Send
from bearcat.bus import keys
from bearcat.bus.messages import Detection, Fix, GameState, Guidance, Message
from bearcat.maps import Map

SPOTTED_FOR = 2.0  # s an agent's screen says a UAV saw it
WARM_UP_ACCURACY = 1.0  # m per axis: the fixes of the warm-up answer, so worst-case answers cover disks


class GuidanceService:
    """Sends each of ``agents`` its guidance: as soon as a new fix of that
    agent arrives (so a phone's answer follows its own fix at once, and no
    faster than its fixes come), and at the scenario's ``rate`` whenever a
    period passed without one (so it also follows the others' moves).
    ``methods`` holds each aided agent's guidance method (None where it
    could not be made: that phone shows no advice) and the guard it is
    called through; it answers from ``advisor``, the game's. An agent
    without one sees positions only. ``tracking``, where some
    method reads the trackers' beliefs, makes the trackers each view of
    the fixes keeps."""

    role = "ground-station"
    watches: tuple[str, ...] = ()

    def __init__(
        self,
        game: str,
        game_map: Map,
        agents,
        *,
        advisor=None,
        methods: dict[str, tuple[GuidanceMethod | None, Guard]] | None = None,
        teams: dict[str, str] | None = None,
        speeds: dict[str, float] | None = None,
        rate: float = 10.0,
        name: str = keys.GROUND,
        sight=None,
        uncertainty=None,
        tracking: Callable[[], Trackers] | None = None,
    ) -> None:
        self.game, self.name, self.map = game, name, game_map
        self.agents = tuple(agents)
        self.advisor = advisor
        self.methods = dict(methods or {})
        self.teams = dict(teams or {})
        self.speeds = dict(speeds or {})
        # The guards' faults, which the runtime records: those of making the methods first.
        self.events: list[PluginFault] = [f for _, guard in self.methods.values() for f in guard.faults]
        self.uncertainty = uncertainty
        self.period = 1.0 / rate
        self.ended = False
        self.sight = sight
        self.subscriptions: tuple[str, ...] = (keys.every(game, "fix"), keys.state(game))
        if sight is not None:
            self.subscriptions += (keys.every(game, "detection"),)

        def view() -> LatestFixes:
            return LatestFixes(game_map, None if tracking is None else tracking())

        self._fresh = view
        self.fixes = view()
        self.known = {a: view() for a in self.agents} if sight is not None else None
        self.spotted: dict[str, tuple[str, float]] = {}  # agent -> (UAV that saw it, when)
        self.seq = 0
        self._last = {a: -np.inf for a in self.agents}

    def start(self, now: float) -> list[Send]:
        return []

    def warm_up(self, starts) -> None:
        """Run the advisor's compiled code, then have each aided agent's
        method answer once with every agent standing at ``starts`` (agent
        -> map point), reported at time 0 on fixes of their own that are
        then dropped. A process's first answer loads compiled solver and
        query code from numba's cache (a fifth to a third of a second in
        every game measured) or, after a fresh clone, compiles it (two
        seconds for capture-the-flag); the ground station does this before
        it says it is up, so no fix of the game waits for it, and this
        first call of each method is the one its guard holds to no budget.
        The advisor then forgets those answers; a method of one's own that
        keeps state has seen this one call."""
        if self.advisor is None:
            return
        self.advisor.warm_up()
        standing = self._fresh()
        for agent, where in starts.items():
            lat, lon = self.map.to_geodetic(*where)
            standing.take(Fix(agent=agent, seq=0, t=0.0, lat=lat, lon=lon, accuracy=WARM_UP_ACCURACY))
        for agent in self.methods:
            self._advise(agent, standing, 0.0)
        self.advisor.forget()

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

    def _advise(self, agent: str, fixes: LatestFixes, now: float) -> Advice:
        """What ``agent``'s method advises from ``fixes`` at ``now``; no advice where it failed."""
        method, guard = self.methods[agent]
        if method is None:
            return NO_ADVICE
        view = GuidanceView(agent, now, self.map, fixes, self.advisor, self.teams, self.speeds)
        before = len(guard.faults)
        advice = guard.call(now, method.advise, view, check=advice_problem, fallback=NO_ADVICE)
        self.events += guard.faults[before:]
        return advice

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
            if agent in self.methods:
                fields = {"game": self.advisor.kind, **msgspec.structs.asdict(self._advise(agent, fixes, now))}
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
