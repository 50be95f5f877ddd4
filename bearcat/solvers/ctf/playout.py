"""Closed-loop play of a solved capture-the-flag game (thesis 3.4): both
players follow the strategies of eqs. 3.12-3.13, or a policy of their own,
and the rules of 3.1.1 referee the result.

The attacker plays the first-stage strategy (from W_A, or F_A) until it
stands in the flag, then the flag-return strategy (from R_A): the switch of
3.3.2. Where W_A is lost but F_A is solved and won, the attacker still goes
for the flag on the F_A strategy, as in thesis Fig. 3.5a: a defender that
wins the whole game then lets it take the flag and blocks the return. Each
step moves a player at its top speed times the terrain factor
where it stands, forward Euler with a step of a quarter cell, so neither can
jump a capture disk or an obstacle edge between referee checks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bearcat.solvers.ctf.queries import CtfQueries, StateReport, interpolate_2d
from bearcat.solvers.errors import InputError

__all__ = ["Playout", "play"]

Policy = Callable[[float, np.ndarray, np.ndarray, str], "tuple[float, float] | None"]
"""``policy(t, attacker, defender, phase)`` -> a heading (unit vector) or None to stand still."""


@dataclass(frozen=True)
class Playout:
    """Positions at ``times``; the phase each step was played in; who won and why."""

    times: np.ndarray
    attacker: np.ndarray
    defender: np.ndarray
    phases: tuple[str, ...]
    winner: str
    reason: str
    flag_time: float | None

    @property
    def duration(self) -> float:
        return float(self.times[-1])


def play(
    queries: CtfQueries,
    attacker,
    defender,
    *,
    phase: str | None = None,
    attacker_policy: Policy | None = None,
    defender_policy: Policy | None = None,
) -> Playout:
    """Play from ``(attacker, defender)`` until somebody wins. ``phase``
    defaults to ``"capture"`` if the solution has a first-stage set, else
    ``"return"``; a game solved for flag capture only ends at the flag."""
    solution = queries.solution
    rules, geometry = solution.rules, queries.geometry
    sets = solution.sets
    two_stage = "return" in sets and ("win" in sets or "capture" in sets)
    if phase is None:
        phase = "capture" if ("win" in sets or "capture" in sets) else "return"
    queries.value_set(phase)  # refuses a phase the solution cannot guide
    state = queries.check_state(attacker, defender)
    xa, xd = state[:2].copy(), state[2:].copy()
    grid = geometry.grid
    lo, spacing = np.asarray(grid.lo), np.asarray(grid.spacing)
    dt = 0.25 * min(grid.spacing) / max(rules.attacker_speed, rules.defender_speed)
    limits = {"capture": rules.capture_time, "return": rules.return_time}

    def inside(field: np.ndarray, p: np.ndarray) -> bool:
        return interpolate_2d(field, lo, spacing, p) <= 0

    def heading(policy, who, report):
        if policy is not None:
            h = policy(t, xa.copy(), xd.copy(), phase)
            if h is None:
                return None
            h = np.asarray(h, float)
            if h.shape != (2,) or not np.isfinite(h).all():
                raise InputError(f"the {who} policy returned {h!r}; it must return a heading (east, north) or None")
            return h / max(float(np.hypot(*h)), 1e-12)
        h = report.attacker_heading if who == "attacker" else report.defender_heading
        return None if h is None else np.asarray(h)

    t, phase_start, flag_time = 0.0, 0.0, None
    times, a_track, d_track, phases = [0.0], [xa.copy()], [xd.copy()], []
    winner: str | None = None
    reason = ""  # set with the winner
    while winner is None:
        if np.hypot(*(xa - xd)) <= rules.capture_radius:
            winner, reason = "defender", "captured"
        elif inside(geometry.flag, xd) or inside(geometry.home, xd):
            winner, reason = "attacker", "defender entered the flag or return region"
        elif phase == "capture" and inside(geometry.flag, xa):
            flag_time = t
            if not two_stage:
                winner, reason = "attacker", "reached the flag"
            else:
                phase, phase_start = "return", t
                continue
        elif phase == "return" and inside(geometry.home, xa):
            winner, reason = "attacker", "returned the flag" if flag_time is not None else "reached the return region"
        elif t - phase_start >= limits[phase] - 1e-9:
            winner, reason = "defender", f"time up in the {phase} stage"
        if winner is not None:
            break
        report = queries.evaluate(xa, xd, phase)
        if phase == "capture" and report.value > 0 and "win" in sets and "capture" in sets:
            grab = queries.evaluate_set("capture", xa, xd)
            if grab.value <= 0:
                report = StateReport(report.value, grab.attacker_heading, report.defender_heading)
        moves = []
        for who, policy, p, speed in (
            ("attacker", attacker_policy, xa, rules.attacker_speed),
            ("defender", defender_policy, xd, rules.defender_speed),
        ):
            h = heading(policy, who, report)
            factor = interpolate_2d(geometry.terrain, lo, spacing, p)
            moves.append(np.zeros(2) if h is None else speed * factor * dt * h)
        xa = np.clip(xa + moves[0], lo, grid.hi)
        xd = np.clip(xd + moves[1], lo, grid.hi)
        if queries.blocked_at(xa):
            winner, reason = "defender", "attacker ran into an obstacle"
        elif queries.blocked_at(xd):
            winner, reason = "attacker", "defender ran into an obstacle"
        t += dt
        times.append(t)
        a_track.append(xa.copy())
        d_track.append(xd.copy())
        phases.append(phase)
    if not phases:
        phases.append(phase)
    return Playout(
        np.asarray(times), np.asarray(a_track), np.asarray(d_track), tuple(phases), winner, reason, flag_time
    )
