"""The opponent shares the bus: attacks from a plain Zenoh client on a live
run without ``--secure``, each of which worked when a name in an attachment
was believed, and each of which must now fail.

One game is played while the intruder forges fixes in the defender's name,
pauses and resumes the game as the launcher, puts the attacker's truth
inside home, declares the game ended with an attacker win, and plays a
genuine guidance again; each test then reads the run directory for one
attack. Every forgery is tried twice: with the name alone, and sealed by a
certificate of an authority of the intruder's own making.
"""

import json
import math
import time

import pytest

from bearcat.agents.ground_station.event_log import read_events
from bearcat.bus import keys
from bearcat.bus.codec import decode, encode
from bearcat.bus.identity import Credentials, make_authority
from bearcat.bus.messages import Control, Fix, GameState, Truth
from bearcat.scenarios.schema import load_scenario
from tests.support.intruder import Intruder
from tests.support.live_runs import game_started, start_launcher
from tests.support.scenario_files import write_scenario

pytestmark = pytest.mark.xdist_group("attacks")  # the module's fixtures are built once, in one xdist worker

GAME = "test-game"
FORGED_FIX = (3.0, 3.0)  # where the forger puts the defender (map metres)
INSIDE_HOME = (25.0, 47.5)
FORGED_REASON = "attacker returned the flag (forged)"


@pytest.fixture(scope="module")
def attacked(tmp_path_factory):
    """Play one game under every attack; the run directory and what the intruder heard."""
    base = tmp_path_factory.mktemp("attacked")
    path = write_scenario(base, time_limit=12.0, netem="ideal")
    scenario = load_scenario(path)
    out = base / "run"
    launcher = start_launcher(path, out)
    names = ("gs", "launcher", "defender", "attacker")
    own = make_authority(base / "intruder-certs", dict.fromkeys(names, "ground-station"))
    try:
        end = time.monotonic() + 120
        while not (out / "endpoint.json").exists() or not game_started(out):
            assert time.monotonic() < end and launcher.poll() is None, "the game never started"
            time.sleep(0.1)
        endpoint = json.loads((out / "endpoint.json").read_text())["endpoint"]
        with Intruder(endpoint) as intruder:
            intruder.tap(keys.guidance(GAME, "attacker"))
            heard_by = time.monotonic() + 15
            while not intruder.samples(keys.guidance(GAME, "attacker")):
                assert time.monotonic() < heard_by, "the intruder heard no guidance to replay"
                time.sleep(0.1)

            def forge(name, key, message):
                payload = encode(message)
                intruder.put(key, payload, name.encode())
                intruder.put(key, payload, Credentials(own, name).seal(key, payload))

            lat, lon = scenario.map.to_geodetic(*FORGED_FIX)
            home_lat, home_lon = scenario.map.to_geodetic(*INSIDE_HOME)
            for k in range(10):
                now = time.time()
                forge(
                    "defender",
                    keys.fix(GAME, "defender"),
                    Fix(agent="defender", seq=10_000 + k, t=now, lat=lat, lon=lon),
                )
                forge(
                    "attacker", keys.truth(GAME, "attacker"), Truth(agent="attacker", t=now, lat=home_lat, lon=home_lon)
                )
                time.sleep(0.1)
            forge("launcher", keys.control(GAME), Control(t=time.time(), command="pause", seq=7))
            time.sleep(1.0)
            forge("launcher", keys.control(GAME), Control(t=time.time(), command="resume", seq=8))
            ended = GameState(
                seq=10**6, t=time.time(), phase="ended", elapsed=3.0, winner="attacker", reason=FORGED_REASON
            )
            forge("gs", keys.state(GAME), ended)
            key, payload, attachment = intruder.samples(keys.guidance(GAME, "attacker"))[0]
            for _ in range(3):
                intruder.put(key, payload, attachment)
                time.sleep(0.1)
            heard = list(intruder.heard)
        output, _ = launcher.communicate(timeout=120)
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()
    assert launcher.returncode == 0, output
    return {"out": out, "scenario": scenario, "heard": heard, "output": output}


def _refused(attacked, peer: str, key: str, claimed: str) -> list[dict]:
    path = attacked["out"] / ("events.jsonl" if peer == "launcher" else f"peers/{peer}.jsonl")
    return [e for e in read_events(path) if e["event"] == "refused" and e["key"] == key and e["sender"] == claimed]


def test_fixes_forged_in_the_defenders_name_never_reach_a_screen(attacked):
    """It worked: the attacker's phone showed the defender where the forger put it."""
    game_map = attacked["scenario"].map
    sent = [e for e in read_events(attacked["out"] / "events.jsonl") if e["event"] == "sent"]
    shown = [
        game_map.to_local(r["lat"], r["lon"])
        for e in sent
        if e["message"]["type"] == "guidance"
        for r in e["message"]["reports"]
        if r["agent"] == "defender"
    ]
    assert shown, "no guidance showed the defender at all"
    assert min(math.dist(p, FORGED_FIX) for p in shown) > 5.0
    refused = _refused(attacked, "gs", keys.fix(GAME, "defender"), "defender")
    # The bare name is no seal; a seal from another authority fails its
    # signature, or, numbered below the defender's last own fix, is refused
    # as old before the signature is even checked.
    reasons = [e["reason"].split(":")[0] for e in refused]
    assert reasons.count("bad seal") == 10 and set(reasons) - {"bad seal"} <= {"forged", "replayed"}
    assert len(refused) == 20


def test_pause_and_resume_in_the_launchers_name_do_not_pause_the_game(attacked):
    """It worked: the game paused and resumed."""
    events = read_events(attacked["out"] / "events.jsonl")
    phases = {e["message"]["phase"] for e in events if e["event"] == "sent" and e["message"]["type"] == "state"}
    assert "running" in phases and "paused" not in phases
    for peer in ("gs", "attacker", "defender", "launcher"):
        assert len(_refused(attacked, peer, keys.control(GAME), "launcher")) == 4, peer


def test_truth_forged_inside_home_wins_nothing(attacked):
    """It worked: the referee declared an attacker win."""
    outcome = json.loads((attacked["out"] / "outcome.json").read_text())
    assert outcome["winner"] == "defender", outcome
    assert len(_refused(attacked, "gs", keys.truth(GAME, "attacker"), "attacker")) == 20
    truths = [
        e["message"]
        for e in read_events(attacked["out"] / "events.jsonl")
        if e["event"] == "sent" and e["key"] == keys.truth(GAME, "attacker")
    ]
    game_map = attacked["scenario"].map
    assert all(game_map.to_local(t["lat"], t["lon"])[1] < 45.0 for t in truths)


def test_a_forged_end_of_the_game_is_not_its_outcome(attacked):
    """It worked: outcome.json recorded the forged winner and reason, crediting the ground station."""
    outcome = json.loads((attacked["out"] / "outcome.json").read_text())
    assert outcome["reason"] != FORGED_REASON and outcome["winner"] == "defender"
    for peer in ("launcher", "attacker", "defender"):
        assert len(_refused(attacked, peer, keys.state(GAME), "gs")) == 2, peer


def test_a_genuine_message_played_again_is_refused(attacked):
    key = keys.guidance(GAME, "attacker")
    replayed = [e for e in _refused(attacked, "attacker", key, "gs") if e["reason"].startswith("replayed")]
    assert len(replayed) == 3


def test_without_secure_an_eavesdropper_still_reads_the_guidance(attacked):
    """What ``--secure`` is for: a seal proves who sent a message, it hides nothing."""
    heard = [decode(payload, key) for key, payload, _ in attacked["heard"]]
    assert heard and all(g.agent == "attacker" for g in heard)
