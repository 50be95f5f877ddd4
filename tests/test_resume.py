"""A run outlives its launcher: a launcher SIGKILLed mid-game takes its
peers with it, each saying so in its log; the checker says the run ended
without a verdict and when; ``bearcat run --resume RUN`` takes the same
run directory up again (the walkers where they stood, the ground station
from its log), the game ends with a verdict the truth agrees with, every
log parses and the gap is recorded. A run that cannot be taken up is
refused in one sentence."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import pytest

from bearcat.agents.ground_station.event_log import read_events
from bearcat.maps import load_map
from bearcat.runtime import processes
from bearcat.runtime.live import LAUNCHER_DIED
from bearcat.suites.checker import check_run
from tests.support.live_runs import start_launcher, wait_for
from tests.support.scenario_files import write_scenario

STARTED = "peers up; game started"


def bearcat(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bearcat", *args], capture_output=True, text=True, timeout=300)


def running(out) -> list[processes.Started]:
    return [p for p in processes.recorded(out) or [] if processes.running(p)]


def truths(events, agent: str) -> list[tuple[float, float, float]]:
    return [
        (e["t"], e["message"]["lat"], e["message"]["lon"])
        for e in events
        if e["event"] == "sent" and e["message"].get("type") == "truth" and e["message"]["agent"] == agent
    ]


def test_a_run_whose_launcher_was_killed_is_taken_up_again_and_ends_with_its_verdict(tmp_path):
    path = write_scenario(tmp_path, time_limit=30.0)
    out = tmp_path / "run"
    launcher = start_launcher(path, out)
    try:
        assert launcher.stdout is not None
        for line in launcher.stdout:
            if STARTED in line:
                break
        refused = bearcat("run", "--resume", str(out))  # while it runs, nothing is taken up
        assert refused.returncode == 2
        assert f"is still running: its launcher (process {launcher.pid}) is alive" in refused.stderr
        launcher.kill()
        launcher.wait()
    finally:
        if launcher.poll() is None:
            launcher.kill()
    # Its peers end with it (the parent-death signal, SIGTERM), each saying why.
    assert wait_for(lambda: running(out) == [], 30.0), running(out)
    for name in ("gs", "attacker", "defender"):
        last = (out / "peers" / f"{name}.log").read_text().splitlines()[-1]
        assert last == f"peer {name}: {LAUNCHER_DIED}"
    findings = {f.name: f for f in check_run(out)}
    assert findings["logs"].held and findings["verdict"].held is None
    assert findings["verdict"].evidence.startswith("ended without a verdict: the launcher died ")
    assert "s into the game, and no bearcat run --resume took the run up" in findings["verdict"].evidence
    before = read_events(out / "events.jsonl")

    resumed = bearcat("run", "--resume", str(out))
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    assert "game taken up again" in resumed.stdout
    outcome = json.loads((out / "outcome.json").read_text())
    assert outcome["ended"] and outcome["winner"] is not None
    events = read_events(out / "events.jsonl")
    assert events[: len(before)] == before  # carried on, appended
    (gap,) = [e for e in events if e["event"] == "resumed"]
    assert gap["since"] == max(e["t"] for e in before) and gap["gap"] == pytest.approx(gap["t"] - gap["since"])
    assert len(json.loads((out / "launch.json").read_text())["launchers"]) == 2
    # The walkers take up where they stood.
    game_map = load_map("field-50")
    for agent in ("attacker", "defender"):
        track = truths(events, agent)
        last = next(p for p in reversed(track) if p[0] <= gap["since"])
        first = next(p for p in track if p[0] >= gap["t"])
        moved = math.dist(game_map.to_local(*last[1:]), game_map.to_local(*first[1:]))
        assert moved < 3.0 * 0.2, (agent, moved)  # at most one tick of walking at top speed
    findings = {f.name: f for f in check_run(out)}
    assert all(f.held is not False for f in findings.values()), findings
    assert findings["logs"].held and findings["verdict"].held and findings["leftovers"].held
    assert running(out) == []


def test_a_run_that_ended_is_not_taken_up(tmp_path):
    path = write_scenario(tmp_path, time_limit=4.0)
    out = tmp_path / "run"
    done = bearcat("run", str(path), "--out", str(out))
    assert done.returncode == 0, done.stdout + done.stderr
    refused = bearcat("run", "--resume", str(out))
    assert refused.returncode == 2
    assert refused.stderr.strip() == (
        f"bearcat: error: {out} ended already (it has its outcome.json): there is nothing to take up"
    )


def test_resume_names_what_it_cannot_take(tmp_path):
    assert bearcat("run", "--resume", str(tmp_path)).stderr.strip() == (
        f"bearcat: error: {tmp_path} is not a run directory: it has no events.jsonl"
    )
    (tmp_path / "events.jsonl").write_text("")
    assert bearcat("run", "--resume", str(tmp_path)).stderr.strip() == (
        f"bearcat: error: {tmp_path} cannot be taken up: it has no launch.json (it was launched before runs kept one)"
    )
    mixed = bearcat("run", "fake-out", "--resume", str(tmp_path))
    assert (
        mixed.returncode == 2
        and "--resume RUN takes the run's own settings: a SCENARIO cannot be given with it" in mixed.stderr
    )
    assert os.path.exists(tmp_path / "events.jsonl") and not (tmp_path / "outcome.json").exists()
