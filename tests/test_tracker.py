"""The ground station's opponent tracker on walks simulated with bearcat's own
models: the walker's body, the phone's GPS and compass errors, the profile's
link delays. Analytic cases first (a standing player, a noise-free straight
walk, the bias's Gauss-Markov steady state), then the order of delivery, the
compass, consistency (NEES), the error against the raw latest fix, and a
feint."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import msgspec
import numpy as np
import pytest
from scipy.linalg import solve_discrete_are
from scipy.stats import chi2

from bearcat.agents.ground_station.tracker import Motion, Tracker, Trackers
from bearcat.agents.human.phone import Phone
from bearcat.agents.human.walker import Walker
from bearcat.bus.messages import Fix
from bearcat.maps import load_map
from bearcat.netem.link import LinkState
from bearcat.netem.models import CompassError, GpsError
from bearcat.netem.profiles import load_profile

FIELD = load_map("field-80x40")  # open: no buildings, so no urban GPS
LO, HI = np.array([5.0, 5.0]), np.array([75.0, 35.0])
TICK = 0.1  # s, the walker's step and the guidance's rate


@dataclass
class Walk:
    """A simulated walk: the truth every tick, the phone's GPS bias then, and
    each fix with the time the ground station receives it."""

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    biases: np.ndarray
    fixes: list[tuple[float, Fix]]  # (received at, fix), in order of receipt


def simulate(
    seed: int,
    profile: str = "wifi",
    *,
    duration: float = 60.0,
    speed: float = 2.0,
    heading_error: float = 10.0,
    legs=None,
    gps: GpsError | None = None,
    compass: CompassError | None = None,
) -> Walk:
    """A person walking from waypoint to waypoint drawn at random over the
    field (or along ``legs``: (from time, direction or None) pairs), carrying
    a phone under ``profile``, its fixes sent over the profile's link."""
    p = load_profile(profile)
    rng = np.random.default_rng(seed)
    body, sensor, network, route = rng.spawn(4)
    start = (5.0, 20.0) if legs is not None else route.uniform(LO, HI)
    walker = Walker(FIELD, start, speed=speed, heading_error=heading_error, rng=body)
    phone = Phone("a", FIELD, gps=gps or p.gps, compass=compass or p.compass, rng=sensor)
    link = LinkState(p.link, network)
    target = route.uniform(LO, HI)
    times, positions, velocities, biases, fixes = [], [], [], [], []
    for k in range(round(duration / TICK)):
        now = k * TICK
        if legs is None:
            if np.hypot(*(target - walker.position)) < 1.0:
                target = route.uniform(LO, HI)
            walker.intend(now, target - walker.position)
        else:
            walker.intend(now, [d for t, d in legs if t <= now + 1e-9][-1])
        walker.step(now, TICK)
        now += TICK
        times.append(now)
        positions.append(walker.position.copy())
        velocities.append(walker.velocity.copy())
        fix = phone.fix(now, walker.position.copy(), walker.heading)
        biases.append(phone.gps.bias.copy())
        if fix is not None:
            fate = link.carry(now, len(msgspec.msgpack.encode(fix)), way="datagram")
            fixes.extend((c.at, fix) for c in fate.copies)
    fixes.sort(key=lambda f: f[0])
    return Walk(np.array(times), np.array(positions), np.array(velocities), np.array(biases), fixes)


def tracker_for(profile: str = "wifi", speed: float = 2.0, heading_error: float = 10.0, **gps) -> Tracker:
    p = load_profile(profile)
    return Tracker(replace(p.gps, **gps) if gps else p.gps, p.compass, Motion.of(speed, heading_error))


def follow(walk: Walk, tracker: Tracker, every: int = 1):
    """Feed ``tracker`` the fixes as they arrive and predict at every
    ``every``-th tick: (tick index, belief, the latest fix's position) each."""
    out, i, latest = [], 0, None
    for k, now in enumerate(walk.times):
        while i < len(walk.fixes) and walk.fixes[i][0] <= now + 1e-9:
            fix = walk.fixes[i][1]
            tracker.take(fix, FIELD)
            if latest is None or fix.t > latest.t:
                latest = fix
            i += 1
        if latest is not None and k % every == 0:
            out.append((k, tracker.predict(now), np.array(FIELD.to_local(latest.lat, latest.lon))))
    return out


def feed(tracker: Tracker, fixes) -> None:
    for fix in fixes:
        tracker.take(fix, FIELD)


# ---------------------------------------------------------------- analytic


def test_a_standing_players_estimate_converges():
    """White GPS noise only, a player who stands. With manoeuvres ruled out
    the tracker is the constant-velocity Kalman filter and settles at its
    steady state (the discrete Riccati equation's solution); with them it is
    wider but still tighter than one fix, and on the player, velocity zero."""
    gps = GpsError(noise_sigma=2.0)
    walk = simulate(1, duration=120.0, legs=[(0.0, None)], gps=gps)
    compass = load_profile("wifi").compass
    motion = Motion.of(2.0)
    walking_only = Tracker(gps, compass, replace(motion, onset=0.0))
    feed(walking_only, [f for _, f in walk.fixes])
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    Q = motion.walk * np.array([[1.0 / 3.0, 0.5], [0.5, 1.0]])
    prior = solve_discrete_are(F.T, np.array([[1.0], [0.0]]), Q, np.array([[gps.noise_sigma**2]]))
    gain = prior[:, :1] / (prior[0, 0] + gps.noise_sigma**2)
    steady = prior - gain @ prior[:1, :]
    belief = walking_only.predict(walk.fixes[-1][1].t)
    assert belief.manoeuvre < 1e-12
    for axis in (0, 1):
        np.testing.assert_allclose(belief.covariance[np.ix_([axis, 2 + axis], [axis, 2 + axis])], steady, rtol=1e-4)
    tracker = Tracker(gps, compass, motion)
    feed(tracker, [f for _, f in walk.fixes])
    belief = tracker.predict(walk.fixes[-1][1].t)
    sigma = math.sqrt(np.trace(belief.position_covariance) / 2.0)
    assert math.sqrt(steady[0, 0]) < sigma < 0.85 * gps.noise_sigma
    assert np.hypot(*(belief.position - walk.positions[-1])) < 3.0 * sigma
    assert np.hypot(*belief.velocity) < 0.3


def test_a_noise_free_straight_walk_is_tracked_exactly():
    """No GPS, compass or heading error: position and velocity are the
    truth's, and so is the prediction two seconds on."""
    walk = simulate(
        2, duration=40.0, speed=1.5, heading_error=0.0, legs=[(0.0, (1.0, 0.0))], gps=GpsError(), compass=CompassError()
    )
    tracker = Tracker(GpsError(), CompassError(), Motion.of(1.5, 0.0))
    feed(tracker, [f for _, f in walk.fixes])
    now = walk.times[-1]
    belief = tracker.predict(now)
    np.testing.assert_allclose(belief.velocity, walk.velocities[-1], atol=1e-3)
    np.testing.assert_allclose(belief.position, walk.positions[-1], atol=1e-3)
    ahead = tracker.predict(now + 2.0)
    np.testing.assert_allclose(ahead.position, walk.positions[-1] + 2.0 * walk.velocities[-1], atol=1e-3)
    assert belief.manoeuvre < 0.1


def test_the_bias_is_known_only_through_its_gauss_markov_prior():
    """The fixes see position plus bias: the bias's mean stays at zero and
    its variance near the process's steady state (the motion model tells a
    little of it apart: never more than a quarter), and with no fixes it goes
    back to exactly that state, ``sigma^2 + (P0 - sigma^2) exp(-2 t / tau)``."""
    p = load_profile("wifi")
    walk = simulate(3, duration=60.0)
    tracker = tracker_for()
    feed(tracker, [f for _, f in walk.fixes])
    steady = p.gps.bias_sigma**2
    belief = tracker.predict(walk.times[-1])
    variances = np.diag(belief.bias_covariance)
    assert np.all((0.75 * steady < variances) & (variances <= steady * (1.0 + 1e-9)))
    assert np.hypot(*belief.bias) < 0.5 * p.gps.bias_sigma
    p0 = np.diag(belief.bias_covariance)
    for later in (10.0, 60.0, 600.0):
        expected = steady + (p0 - steady) * math.exp(-2.0 * later / p.gps.tau)
        got = np.diag(tracker.predict(walk.times[-1] + later).bias_covariance)
        np.testing.assert_allclose(got, expected, rtol=1e-9)


# ---------------------------------------------------------------- delivery


def test_a_late_fix_gives_the_estimate_of_in_order_delivery():
    walk = simulate(4, duration=30.0)
    fixes = sorted({f.seq: f for _, f in walk.fixes}.values(), key=lambda f: f.t)
    shuffled = list(fixes)
    for i in range(3, len(shuffled) - 3, 5):  # every fifth fix two or three places late
        late = shuffled.pop(i)
        shuffled.insert(i + 2 + i % 2, late)
    assert shuffled != fixes
    in_order, out_of_order = tracker_for(), tracker_for()
    feed(in_order, fixes)
    assert all(out_of_order.take(f, FIELD) for f in shuffled)
    for dt in (0.0, 1.5):
        a, b = in_order.predict(fixes[-1].t + dt), out_of_order.predict(fixes[-1].t + dt)
        np.testing.assert_allclose(b.position, a.position, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.covariance, a.covariance, rtol=0, atol=1e-9)
        assert b.manoeuvre == pytest.approx(a.manoeuvre, abs=1e-12)
    assert not out_of_order.take(fixes[-1], FIELD)  # a duplicate
    assert not out_of_order.take(fixes[0], FIELD)  # older than the buffer
    last = fixes[-1].t
    np.testing.assert_allclose(out_of_order.predict(last).position, in_order.predict(last).position, atol=1e-9)


def test_trackers_keep_one_tracker_per_player():
    walk = simulate(5, duration=10.0)
    trackers = Trackers(FIELD, load_profile("wifi").gps, load_profile("wifi").compass)
    assert trackers.predict(0.0) == {}
    for _, fix in walk.fixes:
        trackers.take(fix)
        trackers.take(msgspec.structs.replace(fix, agent="b", lat=fix.lat + 1e-4))
    beliefs = trackers.predict(walk.times[-1])
    assert set(beliefs) == {"a", "b"}
    north = beliefs["b"].position[1] - beliefs["a"].position[1]
    assert north == pytest.approx(11.1, abs=0.1)  # 1e-4 degrees of latitude


# ---------------------------------------------------------------- compass


def test_the_compass_says_nothing_while_the_player_stands():
    """Standing after a walk, the phone repeats its last heading: whatever it
    reads, once the tracker sees the player stand, the estimate is that of
    fixes without a compass."""
    walk = simulate(6, duration=40.0, legs=[(0.0, (1.0, 0.5)), (15.0, None)])
    fixes = [f for _, f in walk.fixes]
    settled = [f for f in fixes if f.t <= 20.0]
    standing = [f for f in fixes if f.t > 20.0]
    rng = np.random.default_rng(0)
    with_compass, without = tracker_for(), tracker_for()
    feed(with_compass, settled)
    feed(without, settled)
    feed(with_compass, [msgspec.structs.replace(f, heading=float(rng.uniform(0.0, 360.0))) for f in standing])
    feed(without, [msgspec.structs.replace(f, heading=None) for f in standing])
    a, b = with_compass.predict(walk.times[-1]), without.predict(walk.times[-1])
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.covariance, b.covariance)
    assert np.hypot(*a.velocity) < 0.3


def test_the_compass_is_read_while_the_player_walks():
    """Walking, the compass narrows the direction of motion: the velocity is
    closer to the truth with it than without."""
    errors = {True: [], False: []}
    for seed in range(6):
        walk = simulate(10 + seed, duration=40.0, legs=[(0.0, (1.0, 0.2))])
        for compass in (True, False):
            tracker = tracker_for()
            fixes = [f if compass else msgspec.structs.replace(f, heading=None) for _, f in walk.fixes]
            for fix in fixes:
                tracker.take(fix, FIELD)
                if fix.t > 10.0:
                    k = round(fix.t / TICK) - 1
                    errors[compass].append(np.sum((tracker.predict(fix.t).velocity - walk.velocities[k]) ** 2))
    with_compass, without = (math.sqrt(np.mean(errors[c])) for c in (True, False))
    assert with_compass < 0.9 * without


# ---------------------------------------------------------------- consistency and error


NEES_RUNS = 50


def test_nees_is_within_its_95_percent_band():
    """The position error after prediction to the guidance's moment, weighed
    by the tracker's own covariance, over many seeded walks under 3G: at each
    check time the mean over the runs is chi-square with 2 N degrees over N,
    and it lies within its 95 % band (all but a few of the times, as a band
    does), and so does the mean over all of them."""
    checks = np.arange(10.0, 60.0 + 1e-9, 5.0)
    nees = np.zeros((NEES_RUNS, len(checks)))
    for run in range(NEES_RUNS):
        walk = simulate(100 + run, "3g", duration=60.0, speed=2.5)
        beliefs = {k: b for k, b, _ in follow(walk, tracker_for("3g", 2.5), every=1)}
        for j, t in enumerate(checks):
            k = round(t / TICK) - 1
            d = beliefs[k].position - walk.positions[k]
            nees[run, j] = d @ np.linalg.solve(beliefs[k].position_covariance, d)
    low, high = chi2.ppf([0.025, 0.975], 2 * NEES_RUNS) / NEES_RUNS
    mean = nees.mean(axis=0)
    print(f"NEES band [{low:.2f}, {high:.2f}], per check time {np.round(mean, 2)}, overall {nees.mean():.2f}")
    assert np.mean((low <= mean) & (mean <= high)) >= 0.8
    assert low <= nees.mean() <= high


@pytest.mark.parametrize("profile", ["wifi", "3g"])
def test_the_prediction_to_now_is_nearer_than_the_latest_fix(profile):
    """Asked at the guidance's rate, the tracker's position now is nearer the
    truth than the latest fix delivered (late by its age and the link's
    delay); the bias, which neither can see, is most of both errors."""
    ours, raw, bias = [], [], []
    for seed in range(16):
        walk = simulate(200 + seed, profile, duration=60.0, speed=2.5)
        for k, belief, latest in follow(walk, tracker_for(profile, 2.5), every=2):
            if walk.times[k] < 10.0:
                continue
            ours.append(np.sum((belief.position - walk.positions[k]) ** 2))
            raw.append(np.sum((latest - walk.positions[k]) ** 2))
            bias.append(np.sum(walk.biases[k] ** 2))
    ours_rmse, raw_rmse, bias_rmse = (math.sqrt(np.mean(e)) for e in (ours, raw, bias))
    print(f"{profile}: RMSE tracker {ours_rmse:.2f} m, latest fix {raw_rmse:.2f} m, bias alone {bias_rmse:.2f} m")
    assert ours_rmse < 0.95 * raw_rmse


# ---------------------------------------------------------------- feint


def test_a_feint_widens_the_prediction_at_once_and_it_tightens_after():
    """A fake-out's turn: running one way, then back the other (the feint's
    legs lie 2 x 100 degrees apart). Within two fixes of the turn the
    manoeuvre probability is up and the prediction's spread wider (the
    velocity's most: the position's is mostly the bias, the same throughout);
    after some seconds of running straight both are back."""
    turn = 20.0
    legs = [(0.0, (math.sin(math.radians(80.0)), math.cos(math.radians(80.0)))), (turn, (-1.0, -0.2))]
    walk = simulate(7, duration=35.0, speed=3.0, legs=legs)
    tracker = tracker_for(speed=3.0)
    spread, speed_spread, manoeuvre, at = [], [], [], []
    for _, fix in walk.fixes:
        tracker.take(fix, FIELD)
        belief = tracker.predict(fix.t + 0.5)  # the guidance half a fix interval on
        at.append(fix.t)
        spread.append(math.sqrt(np.trace(belief.position_covariance) / 2.0))
        speed_spread.append(math.sqrt(np.trace(belief.covariance[2:, 2:]) / 2.0))
        manoeuvre.append(belief.manoeuvre)
    at, spread, speed_spread, manoeuvre = map(np.array, (at, spread, speed_spread, manoeuvre))
    turned = turn + 0.4  # the walker's reaction
    before = (at > turn - 8.0) & (at < turn)
    first_two = np.flatnonzero(at > turned)[:2]
    settled = at > turned + 8.0
    print(
        f"before: manoeuvre {manoeuvre[before].max():.2f}, spread {spread[before].mean():.2f} m, "
        f"{speed_spread[before].mean():.2f} m/s; the two fixes after the turn: {np.round(manoeuvre[first_two], 2)}, "
        f"{np.round(spread[first_two], 2)} m, {np.round(speed_spread[first_two], 2)} m/s; "
        f"8 s on: {manoeuvre[settled].max():.2f}, {spread[settled].mean():.2f} m, "
        f"{speed_spread[settled].mean():.2f} m/s"
    )
    assert manoeuvre[before].max() < 0.2
    assert manoeuvre[first_two].max() > 0.5
    assert spread[first_two].max() > 1.2 * spread[before].mean()  # the bias, the same before and after, is most of it
    assert speed_spread[first_two].max() > 2.0 * speed_spread[before].mean()
    assert manoeuvre[settled].max() < 0.2
    assert spread[settled].mean() < 1.05 * spread[before].mean()
    assert speed_spread[settled].mean() < 1.2 * speed_spread[before].mean()


# ---------------------------------------------------------------- ablations (guidance.ablate)


def test_without_prediction_each_belief_stays_at_its_players_latest_fix():
    walk = simulate(5, duration=10.0, speed=2.5)
    gps, compass = load_profile("wifi").gps, load_profile("wifi").compass
    to_now, at_fix = Trackers(FIELD, gps, compass), Trackers(FIELD, gps, compass, to_now=False)
    for _, fix in walk.fixes:
        to_now.take(fix)
        at_fix.take(fix)
    last = max(f.t for _, f in walk.fixes)
    later = last + 2.0
    held = at_fix.predict(later)["a"]
    assert held.t == last
    np.testing.assert_array_equal(held.position, to_now.predict(last)["a"].position)
    moved = to_now.predict(later)["a"]
    assert moved.t == later
    np.testing.assert_allclose(moved.position, held.position + 2.0 * held.velocity, atol=1e-9)


def test_walking_only_never_manoeuvres_and_a_feint_outruns_its_prediction():
    """One mode: the feint's turn leaves the manoeuvre probability at 0, and
    in the two fixes after the turn the walking-only prediction is further
    from the truth than the full model's, which widens and turns faster."""
    turn = 20.0
    legs = [(0.0, (math.sin(math.radians(80.0)), math.cos(math.radians(80.0)))), (turn, (-1.0, -0.2))]
    errors = {"full": [], "walking only": []}
    for seed in range(8):
        walk = simulate(40 + seed, duration=26.0, speed=3.0, legs=legs)
        p = load_profile("wifi")
        trackers = {
            "full": Tracker(p.gps, p.compass, Motion.of(3.0)),
            "walking only": Tracker(p.gps, p.compass, Motion.of(3.0).walking_only()),
        }
        for _, fix in walk.fixes:
            for name, tracker in trackers.items():
                tracker.take(fix, FIELD)
                if turn + 0.4 < fix.t <= turn + 2.5:
                    belief = tracker.predict(fix.t + 0.5)
                    k = round((fix.t + 0.5) / TICK) - 1
                    errors[name].append(np.sum((belief.position - walk.positions[k]) ** 2))
                    if name == "walking only":
                        assert belief.manoeuvre == 0.0
    full, walking = (math.sqrt(np.mean(errors[n])) for n in ("full", "walking only"))
    print(f"after the turn: RMSE {full:.2f} m with the manoeuvre mode, {walking:.2f} m walking only")
    assert full < walking


def test_without_the_bias_state_the_tracker_is_overconfident():
    """The same GPS error taken for white noise (``GpsError.as_white``):
    averaging fixes seems to shrink an error that is in fact a slowly
    drifting bias, so the NEES over the same walks lies above the band the
    full tracker stays in."""
    p = load_profile("3g")
    white = p.gps.as_white()
    assert white.bias_sigma == 0.0 and white.horizontal_sigma() == pytest.approx(p.gps.horizontal_sigma())
    runs, nees = 20, []
    for run in range(runs):
        walk = simulate(100 + run, "3g", duration=40.0, speed=2.5)
        tracker = Tracker(white, p.compass, Motion.of(2.5))
        beliefs = {k: b for k, b, _ in follow(walk, tracker, every=1)}
        for t in np.arange(10.0, 40.0 + 1e-9, 5.0):
            k = round(t / TICK) - 1
            d = beliefs[k].position - walk.positions[k]
            nees.append(d @ np.linalg.solve(beliefs[k].position_covariance, d))
    high = chi2.ppf(0.975, 2 * runs) / runs
    print(f"NEES without the bias state {np.mean(nees):.2f}, the band's top {high:.2f}")
    assert np.mean(nees) > high
