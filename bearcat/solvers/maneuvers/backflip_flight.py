"""Flying the backflip: the full six-state model of eq. 6.3 under random
disturbances inside (or beyond) the design's bounds, with the mode switches
made by the sets or at fixed times.

Two ways to switch:

- ``"sets"``: the thesis's rule (6.1.3). The climb hands over once its
  height and climb rate lie outside ``K1``; the impulse once the attitude
  lies in ``T1`` (inside the drift's capture set by design) and the height
  outside ``K1``; the drift once the attitude lies in ``T2`` and the height
  outside ``K2``. A mode whose handover is not allowed yet goes on.
- ``"timed"``: the same laws switched at fixed times, those of the nominal
  flip (no disturbance) flown with the sets: what a designer without the
  sets would tune.

A flip succeeds when the attitude reaches ``T3`` within the recovery's
horizon; it is unsafe if it touches the ground or, in the recovery, the
unsafe set ``K3``. The motors' spin-down follows eq. 6.6: on entering the
drift both rotors' thrusts fall linearly to zero, so the thrust's angular
acceleration decays at ``alpha`` from what the impulse left.

Disturbances are piecewise constant, each of ``d_x, d_y, d_phi`` redrawn
every ``hold`` seconds at either end of its bound (the extremes push hardest),
scaled by ``scale`` (1 is the design's bound).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from bearcat.solvers.errors import InputError
from bearcat.solvers.maneuvers.backflip import BackflipSets
from bearcat.solvers.maneuvers.planar_quad import (
    CLIMB,
    DRIFT,
    IMPULSE,
    RECOVERY,
    TWO_PI,
    planar,
    thrust_acceleration,
    thrusts,
)

__all__ = ["Flight", "Trials", "fly", "fly_many", "nominal_flight"]

POLICIES = ("sets", "timed")
DONE = 4
STEP = 1e-3  # s, the integration step (RK4 with the inputs held over it)
RECORD = 10  # steps between recorded samples
HOLD = 0.1  # s a disturbance value is held


@dataclass(frozen=True)
class Flight:
    """One flip. ``path`` rows are ``(t, x, x', y, y', phi, phi', mode)``
    every 10 ms; ``switches`` the ``(t, phi, phi', y, y')`` at each handover
    (climb to impulse, impulse to drift, drift to recovery; NaN if never)."""

    path: np.ndarray
    switches: np.ndarray
    reached: bool
    unsafe: bool
    time_in_mode: tuple[float, float, float, float]


@dataclass(frozen=True)
class Trials:
    """Counts over ``trials`` flips: how many reached ``T3`` and how many
    touched the unsafe set, and the first few flights to draw."""

    policy: str
    scale: float
    trials: int
    reached: int
    unsafe: int
    flights: list[Flight]


def nominal_flight(sets: BackflipSets, start_height: float = 1.0) -> Flight:
    """The flip flown with the sets and no disturbance; its switch times are
    what the timed baseline switches at."""
    flight = fly(sets, "sets", np.random.default_rng(0), scale=0.0, start_height=start_height)
    if not flight.reached:
        raise InputError("the nominal flip does not reach T3 with the sets: there are no times to tune a baseline on")
    return flight


def fly(
    sets: BackflipSets,
    policy: str,
    rng: np.random.Generator,
    *,
    scale: float = 1.0,
    times: tuple[float, float, float] | None = None,
    start_height: float = 1.0,
    start: tuple[float, float, float, float] | None = None,
    hold: float = HOLD,
) -> Flight:
    """One flip under ``policy``, disturbances drawn from ``rng`` and held
    ``hold`` seconds (``math.inf``: one constant push for the whole flip).
    It starts hovering at ``start_height``, or at ``start`` =
    ``(phi, phi', y, y')`` in the climb, which hands over at once where the
    height is already safe."""
    if policy not in POLICIES:
        raise InputError(f"a flip switches by {' or '.join(POLICIES)}, not {policy!r}")
    if policy == "timed" and times is None:
        raise InputError("a timed flip needs its three switch times")
    b = sets.design
    limit = 10.0 + b.recovery_horizon
    if not hold > 0:
        raise InputError(f"a disturbance must be held for a positive time, not {hold!r}")
    signs = rng.choice(np.array([-1.0, 1.0]), size=(int(limit / hold) + 2, 3))
    state = np.array([0.0, 0.0, start_height, 0.0, TWO_PI, 0.0])
    if start is not None:
        state[4], state[5], state[2], state[3] = start
    bounds = np.stack([b.disturbance(mode) for mode in (CLIMB, IMPULSE, DRIFT, RECOVERY)]) * scale
    vertical = b.vertical_grid
    path, switches, flags, spent = _fly(
        b.vehicle.array(),
        b.laws.array(),
        bounds,
        signs,
        np.array([[*box.angle, *box.rate] for box in (b.t1, b.t2, b.t3)]),
        np.ascontiguousarray(sets.unsafe["K1"]),
        np.ascontiguousarray(sets.unsafe["K2"]),
        np.ascontiguousarray(sets.unsafe["K3"]),
        np.array(vertical.lo),
        np.array(vertical.spacing),
        sets.alpha,
        policy == "timed",
        np.array(times if times is not None else (0.0, 0.0, 0.0)),
        state,
        hold,
        b.recovery_horizon,
        limit,
    )
    climb, impulse, drift, recovery = (float(s) for s in spent)
    return Flight(path, switches, bool(flags[0]), bool(flags[1]), (climb, impulse, drift, recovery))


def fly_many(
    sets: BackflipSets,
    policy: str,
    trials: int,
    seed: int,
    *,
    scale: float = 1.0,
    times: tuple[float, float, float] | None = None,
    start_height: float = 1.0,
    keep: int = 20,
    done=None,
) -> Trials:
    """``trials`` flips, each with its own stream of ``seed``; ``done()`` is
    called after each (a progress bar)."""
    streams = np.random.SeedSequence(seed).spawn(trials)
    reached = unsafe = 0
    kept: list[Flight] = []
    for stream in streams:
        flight = fly(sets, policy, np.random.default_rng(stream), scale=scale, times=times, start_height=start_height)
        reached += flight.reached
        unsafe += flight.unsafe
        if len(kept) < keep:
            kept.append(flight)
        if done is not None:
            done()
    return Trials(policy, scale, trials, reached, unsafe, kept)


@numba.njit(cache=True)
def _value(field, lo, spacing, y, v):
    """Bilinear value of a set on the vertical grid, clamped to its edges."""
    n0, n1 = field.shape
    s0 = min(max((y - lo[0]) / spacing[0], 0.0), n0 - 1.0)
    s1 = min(max((v - lo[1]) / spacing[1], 0.0), n1 - 1.0)
    i, j = min(int(s0), n0 - 2), min(int(s1), n1 - 2)
    a, c = s0 - i, s1 - j
    return (
        (1 - a) * (1 - c) * field[i, j]
        + a * (1 - c) * field[i + 1, j]
        + (1 - a) * c * field[i, j + 1]
        + a * c * field[i + 1, j + 1]
    )


@numba.njit(cache=True)
def _inside(box, phi, rate):
    return box[0] <= phi <= box[1] and box[2] <= rate <= box[3]


@numba.njit(cache=True)
def _may_hand_over(mode, phi, rate, y, v, boxes, k1, k2, lo, spacing):
    """The sets' rule: the next mode's entry must be safe, and the attitude
    in the current mode's target (the climb has none)."""
    if mode == RECOVERY:
        return False
    unsafe = k2 if mode == DRIFT else k1
    if _value(unsafe, lo, spacing, y, v) <= 0.0:
        return False
    return mode == CLIMB or _inside(boxes[mode - 1], phi, rate)


@numba.njit(cache=True)
def _fly(quad, laws, bounds, signs, boxes, k1, k2, k3, lo, spacing, alpha, timed, times, start, hold, horizon, limit):
    state = start.copy()
    steps = int(limit / STEP)
    path = np.full((steps // RECORD + 2, 8), np.nan)
    switches = np.full((3, 5), np.nan)
    spent = np.zeros(4)
    mode = CLIMB
    entered = 0.0
    t = 0.0
    reached = False
    unsafe = False
    off1 = off2 = 0.0
    off_time = 0.0
    k = np.zeros((4, 6))
    d = np.zeros(3)
    probe = np.zeros(6)
    row = 0
    for step in range(steps):
        if step % RECORD == 0:
            path[row, 0] = t
            path[row, 1:7] = state
            path[row, 7] = mode
            row += 1
        phi, rate, y, v = state[4], state[5], state[2], state[3]
        if y <= 0.0 or (mode == RECOVERY and _value(k3, lo, spacing, y, v) <= 0.0):
            unsafe = True
        if y <= 0.0:
            break
        if timed:
            ready = mode < RECOVERY and t >= times[mode]
        else:
            ready = _may_hand_over(mode, phi, rate, y, v, boxes, k1, k2, lo, spacing)
        nxt = mode + 1 if ready else mode
        if mode == RECOVERY and _inside(boxes[2], phi, rate):
            reached = True
            break
        if mode == RECOVERY and t - entered > horizon:
            break
        if nxt != mode:
            switches[mode, 0] = t
            switches[mode, 1] = phi
            switches[mode, 2] = rate
            switches[mode, 3] = y
            switches[mode, 4] = v
            spent[mode] = t - entered
            if nxt == DRIFT:
                off1, off2 = thrusts(IMPULSE, phi, rate, quad, laws)
                left = thrust_acceleration(off1, off2, quad)
                off_time = -left / alpha if left < 0.0 else 0.0
            mode = nxt
            entered = t
        held = int(t / hold)
        for c in range(3):
            d[c] = signs[held, c] * bounds[mode, c]
        if mode == DRIFT:
            fade = 1.0 - (t - entered) / off_time if off_time > 0.0 else 0.0
            fade = max(fade, 0.0)
            t1, t2 = off1 * fade, off2 * fade
        else:
            t1, t2 = thrusts(mode, phi, rate, quad, laws)
        for s in range(4):
            for i in range(6):
                probe[i] = state[i] + (0.0 if s == 0 else (0.5 if s < 3 else 1.0) * STEP * k[s - 1, i])
            planar(probe, t1, t2, d, quad, k[s])
        for i in range(6):
            state[i] += STEP / 6.0 * (k[0, i] + 2 * k[1, i] + 2 * k[2, i] + k[3, i])
        t = (step + 1) * STEP
    spent[mode] = t - entered
    path[row, 0] = t
    path[row, 1:7] = state
    path[row, 7] = mode
    flags = np.array([reached, unsafe])
    return path[: row + 1], switches, flags, spent
