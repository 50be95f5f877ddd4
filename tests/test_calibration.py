"""Calibrated guidance: the conformal margins, the quantile answers over a
belief, and games that play, replay and calibrate end to end."""

import json
import math
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from bearcat.agents.ground_station.calibration import (
    AGE_EDGES,
    MIN_GAMES,
    Calibration,
    Score,
    conformal_quantile,
    coverage,
    fit,
)
from bearcat.agents.ground_station.event_log import read_events
from bearcat.maps.geodesy import bearing
from tests.support.scenario_files import write_scenario

# --- the margins: split-conformal quantiles per phase and report age ---


def test_the_conformal_quantile_is_the_textbook_rank_and_refuses_too_few_scores():
    errors = np.arange(1.0, 200.0)  # 199 scores: rank ceil(200 x 0.99) = 198
    assert conformal_quantile(errors, 0.01) == 198.0
    assert conformal_quantile(np.arange(98.0), 0.01) is None  # rank 99 of 98
    assert conformal_quantile(np.arange(99.0), 0.01) == 98.0  # the largest, at exactly 1 / alpha - 1 scores


def _scores(games: int, per_game: int, rng, scale=lambda age: 1.0 + age) -> list[Score]:
    """Errors whose spread grows with the report's age, correlated within a game (a per-game offset)."""
    out = []
    for g in range(games):
        offset = rng.normal(0.0, 0.3)
        for k in range(per_game):
            age = float(rng.uniform(0.0, 3.0))
            out.append(Score(g, float(k), "capture", age, 0.0, offset + scale(age) * float(rng.normal())))
    return out


def test_margins_grow_with_age_and_hold_their_promise_on_held_out_games():
    fitted = _scores(300, 40, np.random.default_rng(10))
    calibration = fit(fitted, 0.05)
    margins = calibration.margins["capture"]
    used = [m for m in margins if m is not None]
    assert len(used) == 5 and used == sorted(used)  # the bins up to 3 s, wider with age
    assert all(m is None for m in margins[5:]) and calibration.counts["capture"][5:] == (0,) * 4
    # The true 95 % quantile of offset + (1 + age) z within [0, 0.5 s] lies near 1.645 x 1.29 = 2.1.
    assert 1.8 < margins[0] < 2.5
    checks = [
        c for c in coverage(calibration, fitted, _scores(200, 40, np.random.default_rng(50))) if c.margin is not None
    ]
    assert len(checks) == 5
    # Each interval holds 95 % with 95 % confidence, so a bin may miss one
    # seed in twenty; on these, every bin holds, and together they cover 95 %.
    assert all(c.verdict == "holds" for c in checks), [(c.ages, c.share, c.interval) for c in checks]
    assert sum(c.covered for c in checks) / sum(c.scores for c in checks) == pytest.approx(0.95, abs=0.006)


def test_a_margin_too_small_for_held_out_games_is_found_short():
    fitted = _scores(200, 40, np.random.default_rng(3))
    calibration = fit(fitted, 0.05)
    wider = _scores(200, 40, np.random.default_rng(4), scale=lambda age: 2.0 * (1.0 + age))
    assert {c.verdict for c in coverage(calibration, fitted, wider) if c.margin is not None} == {"short"}


def test_a_bin_of_few_games_gives_no_margin_however_many_answers_it_holds():
    rng = np.random.default_rng(5)
    scores = [
        Score(g, float(k), "return", 0.2, 0.0, float(rng.normal())) for g in range(MIN_GAMES - 1) for k in range(500)
    ]
    assert fit(scores, 0.01).margins["return"][0] is None
    more = scores + [Score(MIN_GAMES, 0.0, "return", 0.2, 0.0, 0.0)]
    assert fit(more, 0.01).margins["return"][0] is not None
    assert fit(more, 0.01).margin("capture", 0.2) is None  # a phase it never saw


def test_a_calibration_reads_back_as_written_and_bins_every_age():
    calibration = fit(_scores(20, 50, np.random.default_rng(6)), 0.1, about={"scenario": "x"})
    again = Calibration.from_json(json.loads(json.dumps(calibration.to_json())))
    assert again == calibration
    assert calibration.bin(-1.0) == 0 and calibration.bin(0.5) == 1 and calibration.bin(1e9) == len(AGE_EDGES) - 2
    with pytest.raises(ValueError):
        Calibration.from_json({"format": 99})


# --- answers over samples of a belief ---


@pytest.fixture(scope="module")
def field_game():
    from bearcat.maps import load_map
    from bearcat.maps.ctf import ctf_geometry
    from bearcat.maps.ctf_rules import default_rules
    from bearcat.solvers.ctf.queries import CtfQueries
    from bearcat.solvers.ctf.sets import solve_ctf

    game_map = load_map("field-50")
    rules = default_rules(game_map, 3.0, 3.0, capture_radius=2.5, return_time=30.0)
    return CtfQueries(solve_ctf(ctf_geometry(game_map, 21), rules, "return", scheme="first"))


def test_sampled_values_are_the_queries_values(field_game):
    from bearcat.solvers.ctf.sampled import SampledCtf

    rng = np.random.default_rng(7)
    attackers = rng.uniform([5, 5], [45, 40], size=(20, 2))
    defenders = rng.uniform([5, 5], [45, 40], size=(20, 2))
    keep = [k for k in range(20) if not (field_game.blocked_at(attackers[k]) or field_game.blocked_at(defenders[k]))]
    values = SampledCtf(field_game).values(attackers[keep], defenders[keep], "return")
    expected = [field_game.evaluate(attackers[k], defenders[k], "return").value for k in keep]
    np.testing.assert_allclose(values, expected, atol=1e-9)


def test_sampled_quantiles_are_numpys(field_game):
    from bearcat.solvers.ctf.sampled import SampledCtf, _row_quantiles

    rng = np.random.default_rng(9)
    for n in (1, 2, 7, 64):
        values = rng.normal(size=(5, n))
        for q in (0.0, 0.01, 0.5, 0.99, 1.0):
            np.testing.assert_allclose(_row_quantiles(values, q), np.quantile(values, q, axis=1), atol=1e-12)
    attackers = np.array([25.0, 22.0]) + rng.normal(0.0, 2.0, size=(64, 2))
    defenders = np.array([25.0, 34.0]) + rng.normal(0.0, 1.0, size=(64, 2))
    sampled = SampledCtf(field_game)
    expected = np.quantile(sampled.values(attackers, defenders, "return"), 0.99)
    assert sampled.quantile(attackers, defenders, 0.99, "return") == pytest.approx(expected, abs=1e-12)


def test_a_quantile_heading_is_never_worse_than_the_plain_one_at_its_own_quantile(field_game):
    from bearcat.solvers.ctf.sampled import SampledCtf

    sampled = SampledCtf(field_game)
    rng = np.random.default_rng(8)
    attackers = np.array([25.0, 22.0]) + rng.normal(0.0, 2.0, size=(64, 2))
    defenders = np.array([25.0, 34.0]) + rng.normal(0.0, 1.0, size=(64, 2))
    plain = field_game.evaluate((25.0, 22.0), (25.0, 34.0), "return").defender_heading
    answer = sampled.answer("defender", attackers, defenders, 0.25, "return", (plain,))
    here = np.quantile(sampled.values(attackers, defenders, "return"), 0.25)
    assert answer.value == pytest.approx(here)

    def after(heading):
        moved = defenders + sampled.step * np.asarray(heading)
        return np.quantile(sampled.values(attackers, moved, "return"), 0.25)

    assert answer.heading is not None and math.hypot(*answer.heading) == pytest.approx(1.0)
    assert after(answer.heading) >= after(plain) - 1e-12
    # One sample: the quantile is that state's value.
    one = sampled.answer("attacker", attackers[:1], defenders[:1], 0.5, "return")
    assert one.value == pytest.approx(field_game.evaluate(attackers[0], defenders[0], "return").value)


def test_ablations_switch_off_the_calibration_and_the_defenders_belief(field_game):
    """``guidance.ablate``: with ``calibration`` the go's margin is the
    tracker's own even though a calibration is there, and the note says it
    was switched off; with ``belief`` the defender steers by the plain
    heading at the prediction and its value is the plain one there."""
    from bearcat.agents.ground_station.guidance.ctf import CtfAdvisor, Estimate
    from bearcat.maps import load_map

    game_map = load_map("field-50")
    scores = [replace(s, phase="return") for s in _scores(200, 40, np.random.default_rng(10), scale=lambda age: 3.0)]
    calibration = fit(scores, 0.05)
    a, d = np.array([25.0, 22.0]), np.array([25.0, 34.0])
    estimate = Estimate(0.0, _standing(a, 2.0), _standing(d, 2.0), 0.2)

    def advisor(*ablate):
        return CtfAdvisor(
            game_map, field_game, attacker="attacker", defender="defender", phase="return",
            calibration=lambda: calibration, alpha=0.05, ablate=ablate,
        )  # fmt: skip

    full, uncalibrated = advisor().calibrated_answer("attacker", estimate), advisor("calibration")
    assert full["margin"] == pytest.approx(calibration.margin("return", 0.2), abs=1e-3) and full["note"] == ""
    own = uncalibrated.calibrated_answer("attacker", estimate)
    assert "switched off" in own["note"] and own["margin"] != full["margin"]
    plain = field_game.evaluate(a, d, "return")
    sampled = advisor().calibrated_answer("defender", estimate)
    believed = advisor("belief").calibrated_answer("defender", estimate)
    assert believed["value"] == pytest.approx(plain.value)
    assert believed["heading"] == pytest.approx(bearing(*plain.defender_heading))
    assert sampled["value"] < plain.value  # the median over a 2 m wide belief, against the value at its centre


def test_a_calibration_is_keyed_by_the_trackers_ablations_only():
    """Switching off a tracker's part changes what a calibration scores, so
    it has a calibration of its own; switching off the calibration or the
    defender's belief does not, and neither does the order of the parts."""
    from bearcat.agents.ground_station.calibration_store import calibrate_command, calibration_key
    from bearcat.netem.profiles import load_profile
    from bearcat.scenarios.cast import ctf_of
    from bearcat.scenarios.schema import load_scenario

    game, profile = ctf_of(load_scenario("go-no-go")).own(), load_profile("3g")
    full = calibration_key(game, profile, 0.01)
    assert calibration_key(game, profile, 0.01, ("calibration", "belief")) == full
    bias = calibration_key(game, profile, 0.01, ("bias",))
    assert bias != full and bias != calibration_key(game, profile, 0.01, ("prediction",))
    both = calibration_key(game, profile, 0.01, ("prediction", "bias"))
    assert both == calibration_key(game, profile, 0.01, ("bias", "prediction", "belief"))
    command = calibrate_command("go-no-go", "3g", ("belief", "bias"))
    assert command == "bearcat calibrate go-no-go --netem 3g --ablate bias"


# --- games: calibrated guidance live in simulation, its replay, the command ---


def test_a_calibrated_game_sends_predictions_and_margins_and_its_replay_reproduces_every_value(tmp_path):
    """Every report carries where the tracker believed the agent was and
    that belief's ellipse; the attacker's go is its value plus the margin
    below zero; and replaying the event log through the scores' path gives,
    guidance by guidance, the value the ground station used."""
    from bearcat.cli.main import main
    from bearcat.netem.profiles import load_profile
    from bearcat.scenarios.cast import ctf_of
    from bearcat.scenarios.schema import load_scenario
    from bearcat.studies.calibration import replay_scores

    path = write_scenario(tmp_path, defender_behaviour="follow-guidance", defender_aided=True, method="calibrated")
    scenario = load_scenario(path)
    assert main(["simulate", str(path), "--seed", "2", "--out", str(tmp_path / "out")]) == 0
    run = tmp_path / "out" / "seed-2"
    recording = (run / "recording.rrd").read_bytes()
    assert b"ground/prediction/attacker" in recording and b"phone/defender/predicted" in recording
    log = list(read_events(run / "events.jsonl"))
    sent = [e for e in log if e["event"] == "sent" and e["message"].get("type") == "guidance"]
    answered = [e["message"] for e in sent if e["message"]["value"] is not None]
    attacker = [m for m in answered if m["agent"] == "attacker"]
    assert len(attacker) > 50 and all(m["margin"] is not None for m in attacker)
    assert all(m["go"] == (m["value"] + m["margin"] < 0) for m in attacker)
    assert all("not calibrated yet" in m["note"] for m in attacker)
    reports = [r for m in answered for r in m["reports"]]
    assert reports and all(r["predicted"] is not None and r["ellipse"][0] >= r["ellipse"][1] > 0 for r in reports)
    queries = ctf_of(scenario).solved()
    scores = replay_scores(scenario, load_profile(scenario.netem), queries, log, 2)
    by_time = {round(m["t"], 6): m["value"] for m in attacker}
    matched = [(s.estimated, by_time[round(s.t, 6)]) for s in scores if round(s.t, 6) in by_time]
    assert len(matched) > 0.9 * len(attacker)
    np.testing.assert_allclose(*zip(*matched), atol=1e-9)


def _bearcat(*words, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "bearcat", *words], capture_output=True, text=True, timeout=600, cwd=cwd, env=os.environ
    )


def test_calibrate_fits_checks_and_stores_a_calibration_the_ground_station_then_uses(tmp_path):
    from bearcat.agents.ground_station.calibration_store import load_calibration
    from bearcat.netem.profiles import load_profile
    from bearcat.runtime.simulate import simulate
    from bearcat.scenarios.cast import ctf_of
    from bearcat.scenarios.schema import load_scenario

    path = write_scenario(tmp_path, defender_behaviour="follow-guidance", defender_aided=True, method="calibrated")
    out = tmp_path / "calibration"
    words = ("calibrate", str(path), "--trials", "12", "--holdout", "4", "--seed", "500", "--alpha", "0.1")
    run = _bearcat(*words, "--workers", "2", "--out", str(out), "--json")
    assert run.returncode == 0, run.stderr
    rows = json.loads(run.stdout)
    assert rows == json.loads((out / "coverage.json").read_text())
    assert {r["phase"] for r in rows} == {"return"} and any(r["margin"] is not None for r in rows)
    assert "seeds 500-511" in run.stderr and "seeds 512-515" in run.stderr
    assert len((out / "scores.jsonl").read_text().splitlines()) == 16
    assert (out / "calibration.png").stat().st_size > 10_000
    scenario = load_scenario(path)
    profile = load_profile(scenario.netem)
    assert load_calibration(ctf_of(scenario).own(), profile, 0.01) is None  # another alpha
    stored = load_calibration(ctf_of(scenario).own(), profile, 0.1)
    assert stored is not None and stored.about["fit_seeds"] == [500, 511]
    # Resumed: nothing is played again.
    again = _bearcat(*words, "--workers", "1", "--out", str(out), "--json")
    assert again.returncode == 0 and json.loads(again.stdout) == rows
    # Trackers with a part switched off get a calibration of their own, beside the full one.
    ablated = _bearcat(*words[:3], "4", "--holdout", "2", *words[6:], "--ablate", "bias", "--out", str(tmp_path / "b"))
    assert ablated.returncode == 0, ablated.stderr
    alone = load_calibration(ctf_of(scenario).own(), profile, 0.1, ("bias",))
    assert alone is not None and alone.about["ablate"] == ["bias"] and alone.about["fit_seeds"] == [500, 503]
    assert load_calibration(ctf_of(scenario).own(), profile, 0.1).about["fit_seeds"] == [500, 511]
    # The ground station answers from it: each go is the value plus that calibration's margin.
    from bearcat.scenarios.variants import vary

    events = tmp_path / "events.jsonl"
    simulate(vary(scenario, {"guidance.alpha": 0.1}), seed=2, events=events)
    attacker = [
        e["message"]
        for e in read_events(events)
        if e["event"] == "sent" and e["message"].get("type") == "guidance" and e["message"]["agent"] == "attacker"
    ]
    margins = {m["margin"] for m in attacker if m["value"] is not None}
    assert margins - {None} <= {round(m, 3) for m in stored.margins["return"] if m is not None}
    assert not any("not calibrated yet" in m["note"] for m in attacker)


def test_calibrate_refuses_a_game_without_calibrated_guidance_in_one_sentence():
    run = _bearcat("calibrate", "pursuit-field", "--trials", "1", "--holdout", "1")
    assert run.returncode == 2
    assert run.stderr.strip().splitlines()[-1].endswith("calibrated guidance is for capture-the-flag, not pursuit")


def _standing(where: np.ndarray, spread: float):
    """A belief of a player standing at ``where``, ``spread`` metres wide."""
    from bearcat.agents.ground_station.tracker import Belief

    covariance = np.diag([spread**2, spread**2, 0.01, 0.01])
    return Belief(
        t=0.0,
        position=where,
        velocity=np.zeros(2),
        covariance=covariance,
        manoeuvre=0.0,
        bias=np.zeros(2),
        bias_covariance=np.eye(2),
        weights=np.array([1.0]),
        means=np.concatenate([where, np.zeros(2)])[None],
        covariances=covariance[None],
    )
