"""A person in the game: a walker carrying a phone and deciding by a behaviour.

Each tick the body moves, its true position goes out on the truth key (for
the referee and the recorder only), the phone sends a fix when one is due,
and the behaviour reads the screen and sets where the body heads next (the
body turns after its reaction delay). Nobody moves before the start
command. Guidance updates the screen; game state tells the phase (who holds
the flag) and when the game is over.

The behaviour is a plug-in, called through a ``Guard``: when it fails, the
person stands still for that tick. What it declares it does (its traits)
is read from its registry entry: a committing behaviour's go is recorded
as the event ``goes`` and goes out with the truth, a telling one's events
are recorded as they appear.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, cast

import numpy as np

from bearcat.agents.guard import Guard, PluginFault
from bearcat.agents.human.behaviour import COMMITS, TELLS, Behaviour, Commits, Situation, Tells, direction_problem
from bearcat.agents.human.phone import Phone
from bearcat.agents.human.walker import Walker
from bearcat.agents.protocol import Send
from bearcat.bus import keys
from bearcat.bus.messages import Control, GameState, Guidance, Message, Truth
from bearcat.maps.geodesy import compass_degrees

TICK = 0.1  # s: the body's integration step and decision rate
FROZEN = 1.0  # s between ticks past which the peer itself stood still (paused, starved), and its body with it


class HumanAgent:
    role = "walker"
    watches: tuple[str, ...] = ()
    period = TICK

    def __init__(
        self,
        game: str,
        walker: Walker,
        phone: Phone,
        behaviour: Behaviour | None,
        situation: Situation,
        *,
        goals: dict[str, object],
        phase: str = "capture",
        traits: frozenset[str] = frozenset(),
        guard: Guard | None = None,
    ) -> None:
        self.game = game
        self.name = situation.agent
        self.walker = walker
        self.phone = phone
        self.behaviour = behaviour  # None: its factory failed, and the person stands
        self.traits = traits
        self.guard = guard or Guard(situation.agent, type(behaviour).__name__)
        self.situation = situation
        self.goals = goals
        self.phase = phase
        self.started = False
        self.ended = False
        self.subscriptions = (keys.guidance(game, self.name), keys.state(game), keys.control(game))
        self._last: float | None = None
        # What the runtime records as events: (t, what) and the guard's PluginFaults.
        self.events: list[tuple[float, str] | PluginFault] = list(self.guard.faults)
        self._told_faults = len(self.guard.faults)
        self._told_events = 0
        self._went = False

    def start(self, now: float) -> list[Send]:
        self._last = now
        return self._report(now)

    def handle(self, key: str, message: Message, now: float) -> list[Send]:
        if isinstance(message, Guidance):
            self.phone.show(message, now)
        elif isinstance(message, Control):
            self.started = self.started or message.command in ("start", "resume")
        elif isinstance(message, GameState):
            self.started = self.started or message.phase == "running"
            if message.phase == "ended":
                self.ended = True
                self.walker.intend(now, None)
            phase = "capture" if message.flag_holder is None else "return"
            if phase != self.phase and phase in self.goals:
                self.phase = phase
                self.situation = replace(self.situation, goal=self.goals[phase])
        return []

    def tick(self, now: float) -> list[Send]:
        # A peer that stood still (a paused process) froze its body with it:
        # on waking the body goes on from where it stood, not along a stale
        # heading for the whole gap.
        dt = min(now - (self._last if self._last is not None else now), FROZEN)
        self._last = now
        if dt > 0:
            self.walker.step(now - dt, dt)
        if self.started and not self.ended:
            self.walker.intend(now, self._decide(now))
        return self._report(now)

    def _decide(self, now: float) -> Any:
        """The behaviour's direction, None (stand) if it has none or failed; what it did goes to ``events``."""
        direction = None
        if self.behaviour is not None:
            me, screen = self.walker.position.copy(), self.phone.screen
            direction = self.guard.call(
                now, self.behaviour.decide, now, me, screen, self.situation, check=direction_problem
            )
            if TELLS in self.traits:
                told = cast(Tells, self.behaviour).events
                self.events += [(now, str(what)) for what in told[self._told_events :]]
                self._told_events = len(told)
            if not self._went and self.going:
                self._went = True
                self.events.append((now, "goes"))
        self.events += self.guard.faults[self._told_faults :]
        self._told_faults = len(self.guard.faults)
        return direction

    def peer(self, key: str, alive: bool, now: float) -> list[Send]:
        return []

    @property
    def committed_at(self) -> float | None:
        """When a committing behaviour committed to its run (a fake-out's go, a go-no-go's go); None before."""
        if self.behaviour is None or COMMITS not in self.traits:
            return None
        return cast(Commits, self.behaviour).committed_at

    @property
    def going(self) -> bool:
        """Whether the behaviour has committed to its run."""
        return self.committed_at is not None

    def resume(self, truth: Truth) -> None:
        """Stand where ``truth``, the last this walker reported before its peer
        went down, says: a person does not go back to the start when the
        phone's app restarts."""
        self.walker.position = np.array(self.walker.map.to_local(truth.lat, truth.lon), dtype=float)

    def _report(self, now: float) -> list[Send]:
        position, heading = self.walker.position, self.walker.heading
        lat, lon = self.walker.map.to_geodetic(position[0], position[1])
        bearing = None if heading is None else compass_degrees(heading)
        truth = Truth(agent=self.name, t=now, lat=lat, lon=lon, heading=bearing, going=self.going)
        out = [Send(keys.truth(self.game, self.name), truth)]
        fix = self.phone.fix(now, np.array(position), heading)
        if fix is not None:
            out.append(Send(keys.fix(self.game, self.name), fix))
        return out
