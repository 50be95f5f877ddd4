"""A guarded bus: a live ``--secure`` run, a real router on ``tls/`` with
mutual TLS and the access control list made from the policy, with real
certificates from ``bearcat certs init``.

While the game is played, plain Zenoh clients try their luck: one with the
attacker's own certificate reads what it can and publishes a fix in the
defender's name and a pause; one whose certificate the authority issued to
a name no rule mentions; one with a certificate from another authority; one
with none.
"""

import json
import math
import time

import pytest
import zenoh

from bearcat.agents.ground_station.event_log import read_events
from bearcat.bus import keys
from bearcat.bus.codec import encode
from bearcat.bus.identity import Credentials, add_members, make_authority
from bearcat.bus.messages import Control, Fix
from bearcat.runtime.credentials import add_to
from bearcat.scenarios.schema import load_scenario
from tests.support.intruder import Intruder
from tests.support.live_runs import game_started, start_launcher
from tests.support.scenario_files import write_scenario

pytestmark = pytest.mark.xdist_group("secure")  # the module's fixtures are built once, in one xdist worker

GAME = "test-game"
FORGED_FIX = (3.0, 3.0)


@pytest.fixture(scope="module")
def guarded(tmp_path_factory):
    base = tmp_path_factory.mktemp("guarded")
    path = write_scenario(base, time_limit=10.0, netem="ideal")
    scenario = load_scenario(path)
    certs = base / "certs"
    add_to(certs, scenario)
    add_members(certs, {"stranger": "walker"})
    foreign = make_authority(base / "foreign", {"attacker": "walker"})
    out = base / "run"
    launcher = start_launcher(path, out, "--secure", "--certs", str(certs))
    found = {"scenario": scenario, "out": out, "refused_at_connection": {}}
    try:
        end = time.monotonic() + 120
        while not game_started(out):
            assert time.monotonic() < end and launcher.poll() is None, "the game never started"
            time.sleep(0.1)
        endpoint = json.loads((out / "endpoint.json").read_text())["endpoint"]
        found["endpoint"] = endpoint
        ca = certs / "ca.pem"
        for label, kw in (
            (
                "another authority",
                {"ca": foreign / "ca.pem", "cert": foreign / "attacker.pem", "key": foreign / "attacker.key"},
            ),
            ("no certificate", {"ca": ca}),
        ):
            try:
                Intruder(endpoint, **kw).__exit__()
                found["refused_at_connection"][label] = False
            except zenoh.ZError:
                found["refused_at_connection"][label] = True
        with (
            Intruder(endpoint, ca=ca, cert=certs / "attacker.pem", key=certs / "attacker.key") as player,
            Intruder(endpoint, ca=ca, cert=certs / "stranger.pem", key=certs / "stranger.key") as stranger,
        ):
            for key in (
                keys.guidance(GAME, "attacker"),
                keys.guidance(GAME, "defender"),
                keys.truth(GAME, "defender"),
                keys.fix(GAME, "defender"),
            ):
                player.tap(key)
            for key in (keys.state(GAME), keys.guidance(GAME, "attacker"), keys.fix(GAME, "attacker")):
                stranger.tap(key)
            player.tap(keys.every(GAME, "guidance"))  # a wildcard the rules allow only in part: it hears nothing more
            time.sleep(0.5)
            lat, lon = scenario.map.to_geodetic(*FORGED_FIX)
            sealed_as_attacker = Credentials(certs, "attacker")
            for k in range(10):
                fix = encode(Fix(agent="defender", seq=10_000 + k, t=time.time(), lat=lat, lon=lon))
                player.put(keys.fix(GAME, "defender"), fix, sealed_as_attacker.seal(keys.fix(GAME, "defender"), fix))
                time.sleep(0.1)
            for command in ("pause", "stop"):
                control = encode(Control(t=time.time(), command=command, seq=9))
                for intruder in (player, stranger):
                    intruder.put(keys.control(GAME), control, b"launcher")
            time.sleep(1.0)
            found["player heard"] = [key for key, _, _ in player.heard]
            found["stranger heard"] = [key for key, _, _ in stranger.heard]
        output, _ = launcher.communicate(timeout=120)
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()
    assert launcher.returncode == 0, output
    found["output"] = output
    return found


def test_a_certificate_from_another_authority_or_none_is_refused_at_connection(guarded):
    assert guarded["endpoint"].startswith("tls/")
    assert guarded["refused_at_connection"] == {"another authority": True, "no certificate": True}


def test_a_player_reads_its_own_guidance_and_not_the_opponents_nor_anyones_truth(guarded):
    heard = guarded["player heard"]
    assert keys.guidance(GAME, "attacker") in heard
    forbidden = {keys.guidance(GAME, "defender"), keys.truth(GAME, "defender"), keys.fix(GAME, "defender")}
    own_forgeries = heard.count(keys.fix(GAME, "defender"))  # a session hears its own puts
    assert not (set(heard) - {keys.fix(GAME, "defender")}) & forbidden
    assert own_forgeries <= 10


def test_a_player_cannot_publish_a_fix_in_the_opponents_name(guarded):
    out, game_map = guarded["out"], guarded["scenario"].map
    events = read_events(out / "events.jsonl")
    shown = [
        game_map.to_local(r["lat"], r["lon"])
        for e in events
        if e["event"] == "sent" and e["message"]["type"] == "guidance"
        for r in e["message"]["reports"]
        if r["agent"] == "defender"
    ]
    assert shown and min(math.dist(p, FORGED_FIX) for p in shown) > 5.0
    # The router dropped them: no peer even had one to refuse.
    for log in (out / "events.jsonl", out / "peers" / "gs.jsonl"):
        assert not [e for e in read_events(log) if e["event"] == "refused"], log


def test_neither_a_player_nor_a_stranger_can_send_control(guarded):
    events = read_events(guarded["out"] / "events.jsonl")
    phases = {e["message"]["phase"] for e in events if e["event"] == "sent" and e["message"]["type"] == "state"}
    assert "running" in phases and "paused" not in phases
    outcome = json.loads((guarded["out"] / "outcome.json").read_text())
    assert outcome["reason"].startswith("time limit") or "captured" in outcome["reason"], outcome


def test_a_name_no_rule_mentions_gets_nothing(guarded):
    assert guarded["stranger heard"] == []
