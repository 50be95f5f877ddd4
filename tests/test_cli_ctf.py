"""``bearcat solve|query|play ctf`` as a user runs them: real processes, a
real cache directory, real files."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

GAME = ("--map", "ctf-10", "--grid", "17", "--scheme", "first", "--capture-radius", "1.0")


def bearcat(*words: str, cache) -> subprocess.CompletedProcess:
    env = dict(os.environ, BEARCAT_CACHE_DIR=str(cache))
    return subprocess.run(
        [sys.executable, "-m", "bearcat", *words], capture_output=True, text=True, timeout=300, env=env
    )


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One cache for the module: the first command solves, the rest load."""
    path = tmp_path_factory.mktemp("cache")
    run = bearcat("solve", "ctf", *GAME, "--stages", "all", cache=path)
    assert run.returncode == 0, run.stderr
    return path


def test_solve_reports_each_set_and_a_second_call_loads_it(cache, tmp_path):
    out = tmp_path / "solve.json"
    run = bearcat("solve", "ctf", *GAME, "--stages", "all", "--json", str(out), cache=cache)
    assert run.returncode == 0, run.stderr
    report = json.loads(out.read_text())
    sets = {row["set"]: row for row in report["sets"]}
    assert set(sets) == {"R_A", "F_A", "W_A"}
    assert all(row["source"] == "cache" for row in sets.values())
    # Winning the two-stage game is harder than either stage alone.
    assert 0 < sets["W_A"]["attacker_wins_fraction"] < sets["F_A"]["attacker_wins_fraction"]
    assert sets["W_A"]["attacker_wins_fraction"] < sets["R_A"]["attacker_wins_fraction"] < 1
    assert "loaded from cache" in run.stdout


def test_a_local_solve_is_cached_apart_and_reports_its_node_updates(cache, tmp_path):
    """``--local`` solves the same game by the narrow band: its own cache
    entries (the full grid's stay loaded), the same winners up to the
    boundary, fewer node updates than the full grid's steps times nodes."""
    reports = {}
    for flags in ((), ("--local",)):
        out = tmp_path / f"solve{len(flags)}.json"
        run = bearcat("solve", "ctf", *GAME, "--stages", "all", *flags, "--json", str(out), cache=cache)
        assert run.returncode == 0, run.stderr
        reports[bool(flags)] = json.loads(out.read_text())
    full, local = ({row["set"]: row for row in reports[k]["sets"]} for k in (False, True))
    assert reports[True]["local"] and not reports[False]["local"]
    assert all(row["source"] == "cache" for row in full.values())
    assert all(row["source"] == "solved" for row in local.values())
    for name, row in local.items():
        assert 0 < row["node_updates"] <= row["steps"] * 17**4
        assert full[name]["margin_ceiling_m"] is None and 0 < row["margin_ceiling_m"] < 10
        assert row["attacker_wins_fraction"] == pytest.approx(full[name]["attacker_wins_fraction"], abs=0.01)


def test_solve_shows_progress_for_a_set_it_solves(tmp_path):
    run = bearcat("solve", "ctf", *GAME, "--stages", "return", cache=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "R_A" in run.stderr and "game time" in run.stderr
    assert "R_A: attacker wins from" in run.stdout


def test_query_names_the_winner_and_headings_in_json(cache):
    # The attacker next to its return strip, the defender far south: the
    # attacker walks home.
    run = bearcat(
        "query",
        "ctf",
        *GAME,
        "--stages",
        "all",
        "--phase",
        "return",
        "--attacker",
        "5,8",
        "--defender",
        "5,1",
        "--json",
        cache=cache,
    )
    assert run.returncode == 0, run.stderr
    answer = json.loads(run.stdout[run.stdout.index("{") :])
    assert answer["winner"] == "attacker" and answer["value_m"] < 0
    heading = answer["attacker_heading"]
    assert heading["north"] > 0.9 and (heading["bearing_deg"] < 30 or heading["bearing_deg"] > 330)
    assert answer["defender_region_area_m2"] > 0 and answer["regions"]["defender"]


def test_query_a_blocked_return_is_the_defenders(cache, tmp_path):
    plot = tmp_path / "slice.png"
    run = bearcat(
        "query",
        "ctf",
        *GAME,
        "--stages",
        "all",
        "--phase",
        "return",
        "--attacker",
        "5,3",
        "--defender",
        "5,7.5",
        "--json",
        "--plot",
        str(plot),
        cache=cache,
    )
    assert run.returncode == 0, run.stderr
    answer = json.loads(run.stdout[run.stdout.index("{") : run.stdout.rindex("}") + 1])
    assert answer["winner"] == "defender" and answer["value_m"] > 0
    assert plot.stat().st_size > 10_000


def test_query_robust_answers_hold_for_the_disks_the_fixes_allow(cache, tmp_path):
    """Fresh exact fixes give the plain answer; fixes two seconds old (1 m/s
    players) and 0.2 m off give disks of 2 + 2.448 x 0.2 m, and worst cases
    no better for either side than the plain value."""
    state = ("--stages", "all", "--phase", "return", "--attacker", "5,5", "--defender", "3,7")

    def query(*extra):
        run = bearcat("query", "ctf", *GAME, *state, "--guidance", "worst-case", *extra, "--json", cache=cache)
        assert run.returncode == 0, run.stderr
        return json.loads(run.stdout)

    fresh = query("--attacker-age", "0", "--defender-age", "0")
    assert fresh["robust"]["attacker"]["worst_value_m"] == pytest.approx(fresh["value_m"], abs=1e-3)
    assert fresh["robust"]["defender"]["worst_value_m"] == pytest.approx(fresh["value_m"], abs=1e-3)
    assert not fresh["robust"]["attacker"]["uncertain"]
    plot = tmp_path / "robust.png"
    stale = query("--attacker-age", "2", "--defender-age", "2", "--accuracy", "0.2", "--plot", str(plot))
    robust = stale["robust"]
    assert robust["attacker"]["radius_m"] == pytest.approx(2 + 2.448 * 0.2, abs=1e-3)
    assert robust["attacker"]["worst_value_m"] >= stale["value_m"] >= robust["defender"]["worst_value_m"]
    assert robust["attacker"]["wins"] == (robust["attacker"]["worst_value_m"] <= 0)
    assert plot.stat().st_size > 10_000


def test_play_writes_tracks_and_a_figure(cache, tmp_path):
    plot, out = tmp_path / "play.png", tmp_path / "play.json"
    run = bearcat(
        "play",
        "ctf",
        *GAME,
        "--stages",
        "all",
        "--attacker",
        "5,8",
        "--defender",
        "5,1",
        "--plot",
        str(plot),
        "--json",
        str(out),
        cache=cache,
    )
    assert run.returncode == 0, run.stderr
    game = json.loads(out.read_text())
    assert game["winner"] in ("attacker", "defender")
    assert len(game["attacker"]) == len(game["defender"]) == len(game["times_s"]) > 1
    assert plot.stat().st_size > 10_000


@pytest.mark.parametrize(
    "words, culprit",
    [
        (("--map", "nowhere-7", "--attacker", "1,1", "--defender", "2,2"), "nowhere-7"),
        (("--map", "square-10", "--attacker", "1,1", "--defender", "2,2"), "flag region"),
        (("--map", "ctf-10", "--attacker", "11,1", "--defender", "2,2"), "attacker at (11.0, 1.0) is outside the area"),
        (
            ("--map", "campus-200", "--attacker", "50,150", "--defender", "100,100"),
            "defender at (100.0, 100.0) is inside",
        ),
        (("--map", "ctf-10", "--grid", "400", "--attacker", "1,1", "--defender", "2,2"), "GB"),
        (("--map", "ctf-10", "--grid", "5", "--attacker", "1,1", "--defender", "2,2"), "--grid 5"),
        (
            ("--map", "ctf-10", "--grid", "15", "--attacker", "1,1", "--defender", "2,2"),
            "--grid 15 is too coarse for a capture radius of 0.5 m: its cells on map ctf-10 are 0.71 m; use --grid 21",
        ),
    ],
)
def test_bad_input_is_one_sentence_naming_the_culprit(words, culprit, tmp_path):
    run = bearcat("query", "ctf", "--scheme", "first", *words, cache=tmp_path)
    assert run.returncode == 2, run.stdout + run.stderr
    message = run.stderr.strip().splitlines()[-1]
    assert message.startswith("bearcat: error:") and culprit in message
