"""A live run's steps one at a time (``runtime.live_run``), on a real router
on the loopback with real client sessions and processes standing in for
the peers, rather than through a whole launched game (``test_live``)."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import time
from contextlib import closing

from bearcat.agents.ground_station.event_log import EventLog, read_events
from bearcat.bus import keys
from bearcat.bus.codec import decode, encode
from bearcat.bus.messages import GameState
from bearcat.bus.zenoh_session import ZenohSession, config
from bearcat.runtime.live_run import LiveRun, RunSettings
from bearcat.runtime.peer_commands import free_port
from bearcat.runtime.peers import LocalPeers
from bearcat.scenarios.faults import LAUNCHER
from bearcat.scenarios.schema import load_scenario
from tests.support.live_runs import wait_for

SCENARIO = load_scenario("fake-out")  # a referee, a ground station, an attacker and a defender


def a_run(tmp_path, said: list[str]):
    """A LiveRun of the fake-out on a router at a free port, and what it needs closed."""
    out = tmp_path / "run"
    (out / "peers").mkdir(parents=True)
    settings = RunSettings(SCENARIO, "fake-out", out, (), seed=0, netem="ideal", transport="tcp", say=said.append)
    places = LocalPeers(free_port())
    session = ZenohSession(LAUNCHER, config(listen=places.listen, mode="router"))
    record = EventLog(out / "events.jsonl")
    return LiveRun(settings, places, session, record, tmp_path / "certs", []), places, session, record


def test_a_peer_that_dies_before_the_start_is_named_and_the_outcome_kept(tmp_path):
    said: list[str] = []
    run, _places, session, record = a_run(tmp_path, said)
    with session, closing(record):
        run.children["attacker"] = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
        assert run.await_up() == "peer attacker exited with code 3 before the start"
        outcome = run.stop("peer attacker exited with code 3 before the start")
    assert (outcome.ended, outcome.winner, outcome.peers) == (False, None, {"attacker": 3})
    assert outcome.reason == "peer attacker exited with code 3 before the start" and outcome.elapsed == 0.0
    assert json.loads((tmp_path / "run" / "outcome.json").read_text())["reason"] == outcome.reason
    (noted,) = [e for e in read_events(tmp_path / "run" / "events.jsonl") if e["event"] == "outcome"]
    assert noted["peers"] == {"attacker": 3}


def test_a_run_starts_when_every_token_is_up_and_ends_on_the_referees_word(tmp_path):
    said: list[str] = []
    run, places, session, record = a_run(tmp_path, said)
    game = SCENARIO.name
    with (
        session,
        closing(record),
        ZenohSession("referee", config(connect=[places.loopback])) as referee,
    ):
        heard: list = []
        referee.subscribe(keys.control(game), lambda key, payload, sender: heard.append(decode(payload, key)))
        for key in sorted(run.expected)[:-1]:
            referee.declare_token(key)
        run.settings = dataclasses.replace(run.settings, startup=1.0)
        start = time.monotonic()
        last = sorted(run.expected)[-1]
        assert run.await_up() == f"peers not up after 1 s: {last.rsplit('/', 1)[-1]}"
        assert time.monotonic() - start < 5
        referee.declare_token(last)
        assert run.await_up() is None
        run.begin()
        assert wait_for(lambda: [m.command for m in heard] == ["start"], 10), heard
        assert said[-1] == f"{game}: {len(run.expected)} peers up; game started"
        referee.put(keys.state(game), b"\x00 not a message")
        ended = GameState(seq=1, t=time.time(), phase="ended", elapsed=12.5, winner="defender", reason="captured")
        referee.put(keys.state(game), encode(ended))
        assert run.supervise() is None  # the referee's word ends it, not the launcher
        outcome = run.stop(None)
        time.sleep(0.5)
    assert (outcome.winner, outcome.reason, outcome.elapsed, outcome.ended) == ("defender", "captured", 12.5, True)
    assert [m.command for m in heard] == ["start"], "an ended game needs no stop command"
    events = read_events(tmp_path / "run" / "events.jsonl")
    assert {e["key"] for e in events if e["event"] == "alive"} == run.expected
    (refused,) = [e for e in events if e["event"] == "refused"]
    assert (refused["sender"], refused["key"]) == ("referee", keys.state(game))
