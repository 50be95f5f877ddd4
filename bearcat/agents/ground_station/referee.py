"""The referee: the rules of thesis 3.1.1, judged as the game goes.

Capture-the-flag: the attacker must reach its targets in turn (the flag,
then the return region; only the return region in a game that starts with
the flag taken, as in the field trials of 3.5) without coming within the
capture radius of a defender; a defender that enters the flag or return
region forfeits; the defender wins when the time runs out. Reach-avoid has
the same shape with any targets and no forbidden regions; pursuit has no
targets: the pursuers win by capture, the evader by lasting.

Capture is checked over each step, not only at its ends: both agents moved
in straight lines between two position updates, so the closest approach
between them is exact (the remark at the end of thesis 5.3.1). In
simulation the referee judges on the true positions; against hardware
there are none, and it judges on the fixes and says so in every state it
publishes.

A player whose liveliness token vanishes and does not come back within
``rejoin`` seconds ends the game with that reason: a phone whose app
restarts rejoins, and so do the tokens a referee sees vanish when it is
itself the one that stalled (its process paused, its host overloaded, its
session lost and reopened). While it is away a player neither captures
nor is captured, nor reaches a target: its last position is no body's.
A referee restarted mid-game ``resume``s from the last state it sent:
the phase, the game clock, who holds the flag, who was caught.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from bearcat.agents.protocol import Send
from bearcat.bus import keys
from bearcat.bus.messages import Control, Fix, GameState, Message, Phase, Truth
from bearcat.maps import Map
from bearcat.solvers.pursuit.game import first_contact

STATE_EVERY = 1.0  # s between state messages when nothing changes


@dataclass(frozen=True)
class Contest:
    """Who plays and what counts. ``runners`` are the attackers (or the
    evader), ``chasers`` the defenders (or pursuers); ``targets`` the
    ``(name, geometry)`` a runner must reach in turn; ``forbidden`` the
    regions chasers may not enter; ``teams`` the (runner team, chaser team)
    names; whoever is not caught when ``time_limit`` runs out wins if
    ``lasting_wins`` (pursuit), else the chasers do."""

    runners: tuple[str, ...]
    chasers: tuple[str, ...]
    capture_radius: float
    time_limit: float
    teams: tuple[str, str]
    targets: tuple[tuple[str, shapely.Geometry], ...] = ()
    forbidden: tuple[tuple[str, shapely.Geometry], ...] = ()
    flag_taken: bool = False
    lasting_wins: bool = False


class Referee:
    role = "referee"

    def __init__(
        self,
        game: str,
        game_map: Map,
        contest: Contest,
        *,
        on_truth: bool = True,
        name: str = "referee",
        rejoin: float = 10.0,
    ):
        self.game, self.map, self.contest, self.name = game, game_map, contest, name
        self.rejoin = float(rejoin)
        self.on_truth = on_truth
        source = keys.every(game, "truth" if on_truth else "fix")
        self.subscriptions = (source, keys.control(game))
        self.watches = (keys.every(game, "alive"),)
        self.period = 0.1
        self.phase: Phase = "waiting"
        self.started_at: float | None = None
        self.winner: str | None = None
        self.reason = ""
        self.flag_holder = contest.runners[0] if contest.flag_taken else None
        self.next_target = {r: 0 for r in contest.runners}
        self.captured: list[str] = []
        self.seq = 0
        self.ended_at: float | None = None
        self._now: dict[str, np.ndarray] = {}
        self._judged: dict[str, np.ndarray] = {}
        self._last_sent = -np.inf
        self._changed = True
        self._missing: dict[str, tuple[float, str | None]] = {}  # player -> (since, role) while its token is away
        for _, geometry in (*contest.targets, *contest.forbidden):
            shapely.prepare(geometry)

    # ------------------------------------------------------------------ agent protocol

    def start(self, now: float) -> list[Send]:
        return [self._state(now)]

    def handle(self, key: str, message: Message, now: float) -> list[Send]:
        if isinstance(message, Truth | Fix):
            self._now[message.agent] = np.array(self.map.to_local(message.lat, message.lon))
        elif isinstance(message, Control):
            if message.command == "start" and self.phase == "waiting":
                self.phase, self.started_at, self._changed = "running", now, True
                self._judged = {a: p.copy() for a, p in self._now.items()}
            elif message.command == "pause" and self.phase == "running":
                self.phase, self._changed = "paused", True
            elif message.command == "resume" and self.phase == "paused":
                self.phase, self._changed = "running", True
            elif message.command == "stop" and self.phase != "ended":
                self._end(now, None, message.reason or "stopped")
        return self._maybe_state(now)

    def peer(self, key: str, alive: bool, now: float) -> list[Send]:
        parsed = keys.parse(key)
        if parsed.agent not in (*self.contest.runners, *self.contest.chasers):
            return self._maybe_state(now)
        if alive:
            self._missing.pop(parsed.agent, None)
        elif self.phase != "ended":
            self._missing.setdefault(parsed.agent, (now, parsed.role))
        return self._maybe_state(now)

    def tick(self, now: float) -> list[Send]:
        self._forfeit(now)
        if self.phase == "running":
            self._judge(now)
        return self._maybe_state(now)

    def resume(self, state: GameState) -> None:
        """Take the game up from ``state``, the last this referee sent before it went down."""
        self.seq, self.phase = state.seq, state.phase
        self.started_at = None if state.phase == "waiting" else state.t - state.elapsed
        self.winner, self.reason = state.winner, state.reason
        self.ended_at = state.t if state.phase == "ended" else None
        self.flag_holder = state.flag_holder
        self.captured = list(state.captured)
        names = [name for name, _ in self.contest.targets]
        if state.flag_holder is not None and "flag" in names:
            self.next_target[state.flag_holder] = names.index("flag") + 1
        self._changed = True

    def _forfeit(self, now: float) -> None:
        """End the game for the first player gone for longer than ``rejoin``."""
        for agent, (since, role) in self._missing.items():
            if self.phase != "ended" and now - since >= self.rejoin:
                self._end(now, None, f"{role} {agent} is gone")

    # ------------------------------------------------------------------ the rules

    def _judge(self, now: float) -> None:
        assert self.started_at is not None  # the game is running
        c = self.contest
        here = {a: p for a, p in self._now.items() if a not in self._missing}
        for runner in c.runners:
            if runner in self.captured or runner not in here:
                continue
            r0, r1 = self._judged.get(runner, here[runner]), here[runner]
            for chaser in c.chasers:
                if chaser not in here:
                    continue
                c0, c1 = self._judged.get(chaser, here[chaser]), here[chaser]
                if first_contact(r0, r1, c0, c1, c.capture_radius) is not None:
                    self.captured.append(runner)
                    self._changed = True
                    break
        if self.captured and len(self.captured) == len(c.runners):
            return self._end(now, c.teams[1], f"{', '.join(self.captured)} captured")
        for chaser in c.chasers:
            p = here.get(chaser)
            for name, region in c.forbidden:
                if p is not None and shapely.intersects_xy(region, *p):
                    return self._end(now, c.teams[0], f"{chaser} entered the {name} region")
        for runner in c.runners:
            p = here.get(runner)
            k = self.next_target[runner]
            if runner in self.captured or p is None or k >= len(c.targets):
                continue
            name, region = c.targets[k]
            if shapely.intersects_xy(region, *p):
                self.next_target[runner] = k + 1
                self._changed = True
                if name == "flag" and self.flag_holder is None:
                    self.flag_holder = runner
                if k + 1 == len(c.targets):
                    what = "returned the flag" if self.flag_holder == runner else f"reached the {name} region"
                    return self._end(now, c.teams[0], f"{runner} {what}")
        self._judged = {a: p.copy() for a, p in self._now.items()}
        if now - self.started_at >= c.time_limit:
            winner = c.teams[0] if c.lasting_wins else c.teams[1]
            self._end(now, winner, f"time limit of {c.time_limit:g} s")

    def _end(self, now: float, winner: str | None, reason: str) -> None:
        self.phase, self.winner, self.reason, self.ended_at = "ended", winner, reason, now
        self._changed = True

    # ------------------------------------------------------------------ state messages

    def _maybe_state(self, now: float) -> list[Send]:
        if self._changed or now - self._last_sent >= STATE_EVERY:
            return [self._state(now)]
        return []

    def _state(self, now: float) -> Send:
        self._changed, self._last_sent = False, now
        self.seq += 1
        elapsed = 0.0 if self.started_at is None else (self.ended_at or now) - self.started_at
        state = GameState(
            seq=self.seq,
            t=now,
            phase=self.phase,
            elapsed=max(elapsed, 0.0),
            winner=self.winner,
            reason=self.reason[:200],
            flag_holder=self.flag_holder,
            captured=self.captured[:64],
            judged_on="truth" if self.on_truth else "fixes",
        )
        return Send(keys.state(self.game), state)
