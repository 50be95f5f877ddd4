"""The backflip of thesis 6.1 on a coarse copy of its maneuver file: the
model's invariants, the guarantee the sets give a flip, the checks that
must fail, and the two commands as a user runs them."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from bearcat.scenarios.maneuvers import builtin_dir, load_maneuver, load_or_design, parse_maneuver
from bearcat.solvers.errors import InputError
from bearcat.solvers.maneuvers.backflip_flight import fly, fly_many, nominal_flight
from bearcat.solvers.maneuvers.planar_quad import IMPULSE, Quadrotor, planar

pytestmark = pytest.mark.xdist_group("backflip")  # the module's fixtures are built once, in one xdist worker

BUILTIN = (builtin_dir() / "backflip.toml").read_text()
COARSE_GRIDS = """[grids]
angle = [-40.0, 400.0, 56]
rate = [-800.0, 200.0, 51]
height = [-1.0, 16.0, 35]
climb_rate = [-28.0, 12.0, 41]
"""


def coarse_text() -> str:
    return BUILTIN[: BUILTIN.index("[grids]")] + COARSE_GRIDS


@pytest.fixture(scope="module")
def coarse_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("maneuver") / "backflip-coarse.toml"
    path.write_text(coarse_text())
    return path


@pytest.fixture(scope="module")
def sets(coarse_file):
    """Designed once per session: the commands below find it in the cache."""
    return load_or_design(load_maneuver(str(coarse_file)))[0]


def bearcat(*words: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bearcat", *words], capture_output=True, text=True, timeout=600)


def test_eq_6_3_holds_a_hover_and_lets_go_into_free_fall():
    quad = Quadrotor(1.25, 9.81, 0.25, 0.02255, 0.03, 0.5, 18.4)
    q, out = quad.array(), np.empty(6)
    hover = np.array([0.0, 0.0, 5.0, 0.0, 0.0, 0.0])
    planar(hover, quad.weight / 2, quad.weight / 2, np.zeros(3), q, out)
    assert np.allclose(out, 0.0)
    inverted = np.array([0.0, 0.0, 5.0, -2.0, math.pi, 3.0])
    planar(inverted, 0.0, 0.0, np.zeros(3), q, out)  # motors off: gravity, drag, nothing else
    assert out[3] == pytest.approx(-9.81 + 0.25 * 2.0 / 1.25) and out[5] == pytest.approx(-0.02255 * 3.0 / 0.03)
    planar(hover, 1.0, 3.0, np.zeros(3), q, out)  # T2 > T1 turns counter-clockwise, by l (T2 - T1) / I
    assert out[5] == pytest.approx(0.5 * 2.0 / 0.03)


def test_the_design_holds_and_its_sets_nest_as_the_thesis_draws_them(sets):
    assert sets.holds, [str(c) for c in sets.checks]
    assert [c.inner.split(" ")[0] for c in sets.checks] == ["the", "Reach_T4(T1)", "T2"]
    k1, k2, k3 = (sets.unsafe[k] <= 0 for k in ("K1", "K2", "K3"))
    # Each mode's entry set holds what the next one must avoid: an avoid set
    # only grows backwards in time, and the ground is unsafe everywhere.
    assert (k1 >= k2).all() and (k2 >= k3).all() and k1.sum() > k2.sum() > k3.sum()
    y, _ = sets.design.vertical_grid.mesh()
    assert k3[y <= 0].all()
    # The turn-off decays what the impulse leaves within the spin-down time.
    assert sets.turn_off[0] < sets.turn_off[1] <= 0
    assert -sets.turn_off[0] / sets.alpha == pytest.approx(sets.design.spin_down_time)


def test_a_flip_started_inside_ra_t1_ends_in_t3_and_never_touches_the_unsafe_set(sets):
    """Attitudes well inside RA_T(T1) (a margin of a cell against the
    scheme's smearing), a height outside K1, and disturbances at the design's
    bounds: random extremes switched every 0.02, 0.1 or 0.3 s, or one
    constant push for the whole flip."""
    grid = sets.design.attitude_grid
    impulse = sets.capture["impulse"].value
    phi, rate = grid.mesh()
    near_hover = (phi >= math.radians(330)) & (phi <= math.radians(380)) & (np.abs(rate) <= math.radians(120))
    inside = np.argwhere((impulse <= -0.1) & near_hover)
    assert len(inside) >= 20
    rng = np.random.default_rng(1)
    starts = inside[rng.choice(len(inside), 12, replace=False)]
    safe_height = (10.0, 8.0)
    assert sets.unsafe["K1"][sets.design.vertical_grid.nearest_index(safe_height)] > 0
    flown = 0
    for i, j in starts:
        start = (phi[i, j], rate[i, j], *safe_height)
        for hold in (0.02, 0.1, 0.3, math.inf):
            for draw in range(3):
                flight = fly(sets, "sets", np.random.default_rng([i, j, draw]), start=start, hold=hold)
                assert flight.reached and not flight.unsafe, (np.degrees(start[:2]), hold, draw)
                switched = flight.switches
                assert sets.design.t1.holds(*switched[1, 1:3]) and sets.design.t2.holds(*switched[2, 1:3])
                flown += 1
    assert flown == 12 * 4 * 3


def test_the_sets_switch_where_the_thesis_says_and_the_baseline_at_the_nominal_times(sets):
    nominal = nominal_flight(sets)
    times = nominal.switches[:, 0]
    assert np.all(np.diff(times) > 0) and nominal.reached and not nominal.unsafe
    modes = nominal.path[:, 7]
    assert set(np.unique(modes)) == {0, 1, 2, 3} and np.all(np.diff(modes) >= 0)
    # The attitude turns one way only, from 360 deg down to 0.
    flipping = modes >= IMPULSE
    assert np.all(np.diff(nominal.path[flipping, 5]) <= 1e-9)
    timed = fly(sets, "timed", np.random.default_rng(0), scale=0.0, times=tuple(times))
    assert np.allclose(timed.switches[:, 0], times, atol=2e-3) and timed.reached


def test_a_damaged_cache_entry_is_solved_again_and_replaced(coarse_file, tmp_path, caplog):
    maneuver = load_maneuver(str(coarse_file))
    first, source = load_or_design(maneuver, root=tmp_path)
    assert source == "solved"
    (entry,) = (tmp_path / "maneuver").glob("*.npz")
    entry.write_bytes(entry.read_bytes()[:1000])
    again, source = load_or_design(maneuver, root=tmp_path)
    assert source == "solved" and "unreadable" in caplog.text
    assert np.array_equal(again.unsafe["K1"], first.unsafe["K1"])
    assert load_or_design(maneuver, root=tmp_path)[1] == "cache"


def test_far_beyond_the_bounds_flips_fail_and_the_fixed_times_fail_worse(sets):
    """Not a guarantee, a measurement: at 10x the design's disturbances some
    flips miss T3, and the baseline that cannot wait touches the unsafe set
    at least as often as the sets do."""
    times = tuple(nominal_flight(sets).switches[:, 0])
    by_sets = fly_many(sets, "sets", 60, 3, scale=10.0, times=times)
    by_clock = fly_many(sets, "timed", 60, 3, scale=10.0, times=times)
    assert by_sets.reached < 60 or by_clock.reached < 60
    assert by_clock.unsafe >= by_sets.unsafe


def test_a_recovery_too_short_to_cover_the_drift_target_fails_its_check_naming_both_modes(coarse_file, tmp_path):
    short = tmp_path / "short-recovery.toml"
    short.write_text(coarse_file.read_text().replace("recovery = 4.0", "recovery = 0.3"))
    run = bearcat("solve", "maneuver", str(short), "--json", str(tmp_path / "out.json"))
    assert run.returncode == 1, run.stderr
    assert "FAILS  T2 (the drift's target) is not inside RA_T(T3) (the recovery's capture set)" in run.stdout
    report = json.loads((tmp_path / "out.json").read_text())
    failed = [c for c in report["checks"] if not c["holds"]]
    assert len(failed) == 1 and failed[0]["outside_share"] > 0 and failed[0]["worst"] > 0


def test_solve_maneuver_reports_the_checks_draws_both_figures_and_loads_from_the_cache(sets, coarse_file, tmp_path):
    png = tmp_path / "sets.png"
    run = bearcat("solve", "maneuver", str(coarse_file), "--plot", str(png), "--json")
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    assert report["holds"] and report["source"] == "cache" and len(report["checks"]) == 3
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_play_maneuver_reports_rates_with_intervals_for_both_policies_and_each_scale(sets, coarse_file, tmp_path):
    run = bearcat("play", "maneuver", str(coarse_file), "--trials", "30", "--scale", "1", "2", "--json")
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    rows = {(r["scale"], r["policy"]): r for r in report["rates"]}
    assert set(rows) == {(1.0, "sets"), (1.0, "timed"), (2.0, "sets"), (2.0, "timed")}
    assert rows[(1.0, "sets")]["reached"] == 1.0 and rows[(1.0, "sets")]["unsafe"] == 0.0
    low, high = rows[(1.0, "sets")]["reached_95"]
    assert low < 1.0 == high  # 30 successes out of 30 still leave room below
    assert report["nominal"]["time_in_mode_s"]["impulse"] > 0


@pytest.mark.parametrize(
    ("change", "said"),
    [
        (("thrust = 0.05", "thrust = 1.5"), "noise.thrust"),
        (("T1 = { angle = [300.0, 320.0]", "T1 = { angle = [320.0, 300.0]"), "targets.T1"),
        (("arm = 0.5", "arms = 0.5"), "unknown key 'arms'"),
    ],
)
def test_a_bad_maneuver_file_is_one_sentence_naming_the_key(change, said):
    with pytest.raises(InputError, match=said) as raised:
        parse_maneuver(BUILTIN.replace(*change), "backflip.toml")
    assert str(raised.value).startswith("backflip.toml") and "\n" not in str(raised.value)


def test_an_unknown_maneuver_names_the_built_in_ones():
    run = bearcat("solve", "maneuver", "frontflip")
    assert run.returncode == 2
    assert run.stderr.strip() == (
        "bearcat: error: there is no maneuver 'frontflip': not a built-in one (backflip) nor a file"
    )
