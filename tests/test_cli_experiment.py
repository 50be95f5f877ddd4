"""``bearcat experiment pursuit`` as a user runs it: real worker processes,
a run directory, an interruption and a resume."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from bearcat.studies.pursuit_experiment import PursuitSetup, run_trial, trial_tasks


def bearcat(*words, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "bearcat", *words], capture_output=True, text=True, timeout=600, cwd=cwd
    )


def test_a_small_convex_table_with_histograms_and_one_line_per_trial(tmp_path):
    out = tmp_path / "run"
    run = bearcat(
        "experiment",
        "pursuit",
        "--domain",
        "square-10",
        "--pursuers",
        "1",
        "2",
        "--trials",
        "12",
        "--seed",
        "7",
        "--workers",
        "2",
        "--out",
        str(out),
    )
    assert run.returncode == 0, run.stderr
    lines = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    assert sorted(r["key"] for r in lines) == sorted(f"square-10/{n}/{i}" for n in (1, 2) for i in range(12))
    table = json.loads((out / "table.json").read_text())
    for n in (1, 2):
        row = table[f"square-10/{n}"]
        assert row["trials"] == 12 and row["thesis_percent"] == (91.6, 98.2)[n - 1]
        faster = sum(r["area_faster"] for r in lines if r["pursuers"] == n)
        assert row["area_faster_percent"] == pytest.approx(100 * faster / 12, abs=0.05)
    # Every convex chase ends in capture (Theorem 8 for area pursuit).
    assert all(r["area_time"] is not None for r in lines)
    assert (out / "histograms.png").stat().st_size > 10_000
    assert "| square-10 |" in run.stdout and "(91.6)" in run.stdout


def test_a_trial_gives_the_same_result_alone_as_in_the_batch(tmp_path):
    out = tmp_path / "run"
    assert (
        bearcat(
            "experiment",
            "pursuit",
            "--domain",
            "square-10",
            "--pursuers",
            "2",
            "--trials",
            "4",
            "--seed",
            "3",
            "--out",
            str(out),
        ).returncode
        == 0
    )
    batch = {json.loads(line)["key"]: json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()}
    task = trial_tasks(["square-10"], [2], 4, 3, PursuitSetup())[2]
    assert run_trial(task) == batch[task["key"]]


def test_an_interrupted_run_resumes_without_redoing_trials(tmp_path):
    out = tmp_path / "run"
    words = (
        "experiment",
        "pursuit",
        "--domain",
        "square-10",
        "--pursuers",
        "1",
        "2",
        "3",
        "--trials",
        "200",
        "--workers",
        "2",
        "--out",
        str(out),
    )
    child = subprocess.Popen(
        [sys.executable, "-m", "bearcat", *words],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    trials = out / "trials.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and (not trials.exists() or len(trials.read_text().splitlines()) < 20):
        time.sleep(0.05)
    os.killpg(child.pid, signal.SIGKILL)  # the whole run, workers included, as a lost machine would
    child.wait()
    before = [json.loads(line)["key"] for line in trials.read_text().splitlines() if line.endswith("}")]
    assert 20 <= len(before) < 600
    run = bearcat(*words)
    assert run.returncode == 0, run.stderr
    keys = [json.loads(line)["key"] for line in trials.read_text().splitlines() if line.strip().endswith("}")]
    assert sorted(set(keys)) == sorted(f"square-10/{n}/{i}" for n in (1, 2, 3) for i in range(200))
    assert len(keys) == len(set(keys))
    assert keys[: len(before)] == before


def test_a_run_directory_of_another_setup_and_unknown_domains_are_refused(tmp_path):
    out = tmp_path / "run"
    assert (
        bearcat(
            "experiment", "pursuit", "--domain", "square-10", "--pursuers", "1", "--trials", "2", "--out", str(out)
        ).returncode
        == 0
    )
    other = bearcat(
        "experiment",
        "pursuit",
        "--domain",
        "square-10",
        "--pursuers",
        "1",
        "--trials",
        "2",
        "--dt",
        "0.05",
        "--out",
        str(out),
    )
    assert other.returncode == 2 and "another setup (dt 0.1 -> 0.05)" in other.stderr
    unknown = bearcat("experiment", "pursuit", "--domain", "moon-3", "--out", str(out))
    assert unknown.returncode == 2 and "unknown domain 'moon-3'" in unknown.stderr


def test_a_trial_does_not_depend_on_the_other_domains_of_the_run():
    alone = trial_tasks(["triangle-10"], [2], 3, 5, PursuitSetup())[1]
    among = trial_tasks(["square-10", "maze-10", "triangle-10"], [1, 2], 3, 5, PursuitSetup())
    assert alone in among
