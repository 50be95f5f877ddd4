"""Crashes no fault plan asked for, dealt from outside as the field deals
them: SIGKILL to the ground station at a seeded moment of ten live
fake-out games, and to the UAV peer of live search games. The run's
supervisor starts each again, it resumes from its own log, and every game
still ends with a verdict the truth agrees with, judged by the checker,
with nothing left running."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import threading
import time

import pytest

from bearcat.agents.ground_station.event_log import read_events
from bearcat.runtime import processes
from bearcat.scenarios.schema import load_scenario
from bearcat.suites.checker import check_run
from tests.support.live_runs import start_launcher, wait_for
from tests.support.scenario_files import write_scenario
from tests.support.system import missing_kernel_network

GAMES = 10
AT_ONCE = 5
STARTED = "peers up; game started"


def kill_mid_game(launcher: subprocess.Popen, out, victim: str, moment: float) -> float:
    """SIGKILL peer ``victim`` of the run in ``out`` ``moment`` s after its
    launcher says the game started; when (Unix time) it was killed."""
    assert launcher.stdout is not None
    for line in launcher.stdout:
        if STARTED in line:
            break
    else:
        pytest.fail(f"the launcher ended before the game started (exit {launcher.wait()})")
    time.sleep(moment)
    running = [p for p in processes.recorded(out) or [] if p.name == victim and processes.running(p)]
    assert len(running) == 1, f"{victim} has {len(running)} running processes: {running}"
    peer = running[0]
    killed = time.time()
    os.kill(peer.pid, signal.SIGKILL)
    return killed


def judged(out) -> dict[str, bool | None]:
    findings = check_run(out)
    return {f.name: f.held for f in findings} | {"evidence": "; ".join(f"{f.name}: {f.evidence}" for f in findings)}


def assert_restarted_and_judged(launcher, out, victim: str, killed: float) -> None:
    output, _ = launcher.communicate(timeout=300)
    assert launcher.returncode == 0, output
    outcome = json.loads((out / "outcome.json").read_text())
    assert outcome["ended"] and outcome["winner"] is not None, (outcome["reason"], output)
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    deaths = [e for e in events if e["event"] == "died"]
    assert len(deaths) == 1, (deaths, output)
    death = deaths[0]
    assert death["peer"] == victim and death["code"] == -signal.SIGKILL and death["restart"]
    assert 0.0 <= death["t"] - killed < 1.0  # seen at once: the launcher waits on its child
    findings = judged(out)
    assert findings["supervision"] and findings["verdict"] and findings["leftovers"], findings["evidence"]
    assert all(held is not False for name, held in findings.items() if name != "evidence"), findings["evidence"]


def test_a_ground_station_killed_at_a_random_moment_is_restarted_and_every_fake_out_ends_with_its_verdict(
    tmp_path,
):
    """Ten games, ``AT_ONCE`` at a time: a live game mostly waits on the
    wall clock, so games side by side cost little more than one."""
    failures: dict[int, str] = {}

    def play(game: int) -> None:
        moment = random.Random(game).uniform(0.5, 7.0)
        folder = tmp_path / f"game-{game}"
        folder.mkdir()
        # A player waits a lease for a ground station gone: longer than a restart can take on a loaded machine.
        path = write_scenario(folder, time_limit=20.0, lease=30.0)
        launcher = start_launcher(path, folder / "run", "--seed", str(game))
        try:
            killed = kill_mid_game(launcher, folder / "run", "gs", moment)
            assert_restarted_and_judged(launcher, folder / "run", "gs", killed)
        except BaseException as exc:  # pytest.fail's too: each game's failure is reported with the others'
            failures[game] = f"{type(exc).__name__}: {exc}"
        finally:
            if launcher.poll() is None:
                launcher.kill()
                launcher.wait()

    for wave in range(0, GAMES, AT_ONCE):
        threads = [threading.Thread(target=play, args=(game,)) for game in range(wave, min(wave + AT_ONCE, GAMES))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    assert failures == {}, "\n".join(f"game {game}: {why}" for game, why in sorted(failures.items()))


@pytest.mark.parametrize(
    ("game", "network"),
    [
        (0, "shim"),
        pytest.param(
            1,
            "kernel",
            marks=[
                pytest.mark.xdist_group("kernel"),
                pytest.mark.skipif(missing_kernel_network() is not None, reason=str(missing_kernel_network())),
            ],
        ),
    ],
)
def test_a_uav_peer_killed_at_a_random_moment_is_restarted_and_the_search_ends_with_its_verdict(
    tmp_path, game, network
):
    """``bearcat run`` on the search scenario: a vehicle emulator and a UAV
    peer beside the ground station and the walkers, the UAV armed, flown and
    tasked over MAVLink and Zenoh, killed mid-game and started again (on a
    kernel network, in its vehicle's namespace); every process gone at the end."""
    moment = random.Random(game).uniform(2.0, 10.0)
    # The 35-point game the search-game tests solve too, from the same cache.
    text = (
        load_scenario("search")
        .text.replace("grid = 45", "grid = 35")
        .replace("time_limit = 240.0", "time_limit = 25.0")
    )
    path = tmp_path / "search.toml"
    path.write_text(text)
    out = tmp_path / "run"
    launcher = start_launcher(path, out, "--seed", str(game), "--network", network)
    try:
        killed = kill_mid_game(launcher, out, "q1", moment)
        assert_restarted_and_judged(launcher, out, "q1", killed)
    finally:
        if launcher.poll() is None:
            launcher.kill()
    outcome = json.loads((out / "outcome.json").read_text())
    assert set(outcome["peers"]) >= {"q1", "vehicle-q1"} and all(c == 0 for c in outcome["peers"].values()), outcome
    events = read_events(out / "events.jsonl")
    restarted = next(e["t"] for e in events if e["event"] == "restarted")
    flown = [
        (e["t"], e["message"]["alt"])
        for e in events
        if e["event"] == "sent" and e["message"].get("type") == "truth" and e["message"]["agent"] == "q1"
    ]
    assert max(alt for _, alt in flown) > 15.0
    tasks = [e["t"] for e in events if e["event"] == "sent" and e["message"].get("type") == "uav-task"]
    assert sum(t > restarted for t in tasks) >= 3  # tasked on after its restart
    assert (out / "recording.rrd").exists()


def test_a_ground_station_that_dies_past_its_intensity_ends_the_game_saying_so(tmp_path):
    path = write_scenario(tmp_path, time_limit=60.0)
    path.write_text(path.read_text() + "\n[supervision]\nmax_restarts = 1\nperiod = 600.0\n")
    out = tmp_path / "run"
    launcher = start_launcher(path, out)
    try:
        kill_mid_game(launcher, out, "gs", 1.0)
        assert wait_for(lambda: restarts(out) == 1, 60.0), "the ground station was not started again"
        (again,) = [p for p in processes.recorded(out) or [] if p.name == "gs" and processes.running(p)]
        os.kill(again.pid, signal.SIGKILL)
        output, _ = launcher.communicate(timeout=120)
    finally:
        if launcher.poll() is None:
            launcher.kill()
    outcome = json.loads((out / "outcome.json").read_text())
    why = "peer gs restarted too often: 2 unplanned deaths within 600 s (max_restarts 1), the last with code -9"
    assert not outcome["ended"] and outcome["winner"] is None and outcome["reason"] == why, output
    assert why in output
    findings = judged(out)
    assert findings["supervision"] and findings["verdict"] and findings["logs"] and findings["leftovers"], findings[
        "evidence"
    ]


def restarts(out) -> int:
    events = out / "events.jsonl"
    return sum(e["event"] == "restarted" for e in read_events(events)) if events.exists() else 0
