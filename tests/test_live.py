"""Live runs: every peer a real process on real Zenoh sessions over loopback.
A game finishes, with the ground station's guidance readied before it
starts, and leaves no process behind; a walker killed mid-game is
seen gone within two seconds and ends the game with that reason; garbage
published on every key of the game is dropped and counted while the game
goes on; an agent's exceptions are recorded and counted while its peer goes
on; what reaches a peer while its guidance warms up waits for it; Ctrl-C
stops everything; a person at a terminal steers a keyboard walker; an
agent named with --joins, a walker or a phone's page bridge, is started
by hand and waited for; a client whose router is not there says so in one
sentence."""

import asyncio
import json
import math
import os
import random
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from contextlib import closing
from pathlib import Path

import aiohttp
import pytest

from bearcat.agents.ground_station.event_log import EventLog, read_events
from bearcat.bus import keys
from bearcat.bus.codec import decode, encode
from bearcat.bus.messages import Fix, GameState
from bearcat.bus.zenoh_session import ZenohSession, config
from bearcat.netem.profiles import load_profile
from bearcat.runtime import processes
from bearcat.runtime.live import run_peer
from bearcat.runtime.live_run import agent_failures
from bearcat.runtime.peer_commands import free_port
from bearcat.scenarios.cast import build_cast
from bearcat.scenarios.faults import parse_faults, write_faults
from bearcat.scenarios.schema import load_scenario
from tests.support.faulty import Faulty
from tests.support.live_runs import game_started, printed_command, start_launcher, wait_for
from tests.support.scenario_files import write_scenario


@pytest.fixture
def env(tmp_path_factory):
    return dict(os.environ, BEARCAT_CACHE_DIR=str(tmp_path_factory.getbasetemp() / "cache"), PYTHONUNBUFFERED="1")


def start_run(tmp_path, **kw):
    path = write_scenario(tmp_path, **kw)
    out = tmp_path / "run"
    return start_launcher(path, out), out, path


def peers_of(out) -> list[int]:
    """The processes still running a peer the launcher started for run directory ``out``."""
    found = subprocess.run(["pgrep", "-f", f"bearcat peer --spec {out}/peers/"], capture_output=True, text=True)
    return [int(p) for p in found.stdout.split()]


def test_a_live_game_finishes_records_and_leaves_no_process(tmp_path):
    from bearcat.suites.checker import check_run

    launcher, out, _path = start_run(tmp_path, time_limit=6.0)
    output, _ = launcher.communicate(timeout=180)
    assert launcher.returncode == 0, output
    findings = {f.name: f.held for f in check_run(out)}
    assert findings == {
        "logs": True,
        "reliable": True,
        "verdict": True,
        "detection": None,
        "supervision": None,
        "failsafe": None,
        "plugins": True,
        "leftovers": True,
    }
    outcome = json.loads((out / "outcome.json").read_text())
    assert outcome["ended"] and outcome["winner"] in ("attacker", "defender"), outcome
    assert all(code == 0 for code in outcome["peers"].values()), outcome["peers"]
    assert peers_of(out) == []
    events = read_events(out / "events.jsonl")
    kinds = {e["message"]["type"] for e in events if e["event"] == "sent"}
    assert {"fix", "truth", "guidance", "state", "control"} <= kinds
    assert (out / "recording.rrd").exists() and "bearcat view" in output
    # The ground station says it is up only once its guidance has answered
    # once, so the game's first fixes do not wait for numba to load its code.
    gs = read_events(out / "peers" / "gs.jsonl")
    warmed = [e["t"] for e in gs if e["event"] == "warmed"]
    running = min(e["t"] for e in gs if e["event"] == "sent" and e.get("message", {}).get("phase") == "running")
    assert len(warmed) == 1 and warmed[0] < running, (warmed, running)


def test_a_live_run_logs_each_guidance_body_once(tmp_path):
    """The launcher's run-wide log (what the recording and the checker read)
    holds every guidance the ground station sent; the ground station's own
    log says it sent each (key, number, size) without its body again, and
    no peer's text log copies one either. Ground stations answering fifty
    phones wrote every body twice, gigabytes each."""
    from bearcat.suites.checker import check_run

    launcher, out, _ = start_run(tmp_path, time_limit=6.0)
    output, _ = launcher.communicate(timeout=180)
    assert launcher.returncode == 0, output
    bodies: Counter = Counter()
    for log in (out / "events.jsonl", *sorted((out / "peers").glob("*.jsonl"))):
        for e in read_events(log):
            if e["event"] == "sent" and e.get("message", {}).get("type") == "guidance":
                bodies[(e["sender"], e["key"], e["message"]["seq"])] += 1
    gs = read_events(out / "peers" / "gs.jsonl")
    sent = [e for e in gs if e["event"] == "sent" and "/guidance/" in e["key"]]
    numbers = {(e["sender"], e["key"], e.get("seq", e.get("message", {}).get("seq"))) for e in sent}
    assert len(numbers) == len(sent) > 20  # ten a second to each of two players
    assert {k: n for k, n in bodies.items() if n != 1} == {} and set(bodies) == numbers
    assert all(e["size"] > 0 for e in sent)
    for text in sorted((out / "peers").glob("*.log")):
        assert '"reports"' not in text.read_text() and "Guidance(" not in text.read_text(), text
    # What the checker and the recording read is all still there.
    findings = {f.name: f.held for f in check_run(out)}
    assert findings["logs"] and findings["reliable"] and findings["verdict"], findings
    assert (out / "recording.rrd").stat().st_size > 0


def test_a_walker_killed_mid_game_is_gone_within_two_seconds_and_ends_the_game(tmp_path):
    """A requirement: a SIGKILLed player must be seen gone within two
    seconds, and forfeit once the lease it had to rejoin runs out. The
    socket closes with the process, so Zenoh reports the token gone in
    milliseconds; the margin covers a loaded 2-core machine."""
    launcher, out, _path = start_run(
        tmp_path,
        time_limit=60.0,
        attacker_behaviour="follow-guidance",
        defender_behaviour="follow-guidance",
        defender_aided=True,
        netem="ideal",
        lease=3.0,
    )
    try:
        assert wait_for(lambda: game_started(out), 120), "the game never started"
        time.sleep(1.0)
        (victim,) = [p for p in peers_of(out) if "/peers/defender.spec.json" in Path(f"/proc/{p}/cmdline").read_text()]
        killed = time.time()
        os.kill(victim, signal.SIGKILL)
        output, _ = launcher.communicate(timeout=60)
    finally:
        if launcher.poll() is None:
            launcher.kill()
    outcome = json.loads((out / "outcome.json").read_text())
    assert outcome["ended"] and outcome["winner"] is None and "walker defender is gone" in outcome["reason"], output
    events = read_events(out / "events.jsonl")
    gone = [e for e in events if e["event"] == "gone" and e["key"].endswith("/defender")]
    assert gone[0]["t"] - killed < 2.0
    ended = [e for e in events if e.get("message", {}).get("phase") == "ended"]
    assert 3.0 <= ended[0]["t"] - gone[0]["t"] < 3.0 + 2.0  # the lease to rejoin, then the verdict
    assert peers_of(out) == []


def test_garbage_on_every_key_is_dropped_and_counted_and_the_game_goes_on(tmp_path):
    launcher, out, _path = start_run(tmp_path, time_limit=8.0, netem="ideal")
    try:
        assert wait_for(lambda: game_started(out), 120), "the game never started"
        port = json.loads((out / "endpoint.json").read_text())["endpoint"]
        with ZenohSession("vandal", config(connect=[port])) as vandal:
            rng = random.Random(0)
            game = "test-game"
            targets = [
                keys.fix(game, "attacker"),
                keys.fix(game, "defender"),
                keys.guidance(game, "attacker"),
                keys.guidance(game, "defender"),
                keys.state(game),
                keys.control(game),
                keys.truth(game, "attacker"),
                keys.uav_task(game, "q1"),
            ]
            time.sleep(0.5)
            for k in range(400):
                payload = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 64)))
                vandal.put(targets[k % len(targets)], payload, reliable=k % 2 == 0)
        output, _ = launcher.communicate(timeout=120)
    finally:
        if launcher.poll() is None:
            launcher.kill()
    outcome = json.loads((out / "outcome.json").read_text())
    assert outcome["ended"] and all(code == 0 for code in outcome["peers"].values()), output
    refused = 0
    for name in ("gs", "attacker", "defender"):
        refused += sum(1 for e in read_events(out / "peers" / f"{name}.jsonl") if e["event"] == "refused")
    assert refused > 100


def test_a_flood_on_one_key_costs_its_receivers_a_budget_not_their_disk(tmp_path):
    """Twenty thousand messages a second on the defender's fix key: each
    receiver lets through what one sender may cost, drops the rest before
    decoding it, says so once a second, and the game ends as it would."""
    launcher, out, _path = start_run(tmp_path, time_limit=8.0, netem="ideal")
    sent = 0
    try:
        assert wait_for(lambda: game_started(out), 120), "the game never started"
        port = json.loads((out / "endpoint.json").read_text())["endpoint"]
        with ZenohSession("vandal", config(connect=[port])) as vandal:
            garbage = bytes(range(64))
            end = time.monotonic() + 3.0
            while time.monotonic() < end and sent < 60_000:
                vandal.put(keys.fix("test-game", "defender"), garbage, reliable=False)
                sent += 1
        output, _ = launcher.communicate(timeout=120)
    finally:
        if launcher.poll() is None:
            launcher.kill()
    outcome = json.loads((out / "outcome.json").read_text())
    assert outcome["ended"] and all(code == 0 for code in outcome["peers"].values()), output
    assert sent > 5_000
    gs = read_events(out / "peers" / "gs.jsonl")
    refused = sum(1 for e in gs if e["event"] == "refused" and e["sender"] == "vandal")
    over = sum(e["dropped"] for e in gs if e["event"] == "over-budget" and e["sender"] == "vandal")
    assert refused <= 500 + 100 * 4  # the burst, then the rate, over the flood's three seconds and a margin
    assert over > 0 and refused + over <= sent
    launcher_refused = sum(1 for e in read_events(out / "events.jsonl") if e["event"] == "refused")
    assert launcher_refused <= 500 + 100 * 4


def test_a_peer_whose_agent_raises_records_and_counts_it_and_goes_on(tmp_path):
    """The live runtime in this process on real Zenoh sessions: the ground
    station's guidance service raises on every third fix of the attacker and
    on every fifth tick; it keeps answering, every exception is in the peer's
    event log, and the peer's reason and the launcher's count report them."""
    scenario = load_scenario(write_scenario(tmp_path, netem="ideal"))
    game = scenario.name
    players = build_cast(scenario, load_profile("ideal"), 0, people=[], ground=True)
    fix = keys.fix(game, "attacker")
    faulty = Faulty(players.guidance, fails_on=lambda key, message: key == fix and message.seq % 3 == 0, every=5)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    answers = []

    def play(player):
        """Both players report for three seconds, then the game ends."""
        assert wait_for(lambda: player.alive(keys.every(game, "alive")), 30), "the peer never came up"
        time.sleep(0.5)  # its subscriptions reach this session
        for seq in range(1, 31):
            for agent, (x, y) in (("attacker", (25.0, 22.0 + 0.1 * seq)), ("defender", (25.0, 34.0))):
                lat, lon = scenario.map.to_geodetic(x, y)
                message = Fix(agent=agent, seq=seq, t=time.time(), lat=lat, lon=lon)
                player.put(keys.fix(game, agent), encode(message), reliable=False)
            time.sleep(0.1)
        player.put(keys.state(game), encode(GameState(seq=1, t=time.time(), phase="ended", reason="enough")))

    with (
        ZenohSession("gs", config(listen=[endpoint])) as session,
        ZenohSession("player", config(connect=[endpoint])) as player,
        closing(EventLog(tmp_path / "run" / "peers" / "gs.jsonl")) as record,
    ):
        player.subscribe(keys.guidance(game, "attacker"), lambda k, p, s: answers.append(decode(p, k)))
        players_thread = threading.Thread(target=play, args=(player,))
        players_thread.start()
        reason = asyncio.run(run_peer([faulty], session, game, record=record))
        players_thread.join()
    failed = [e for e in read_events(tmp_path / "run" / "peers" / "gs.jsonl") if e["event"] == "failed"]
    assert faulty.raised > 0 and len(failed) == faulty.raised
    assert {e["key"] for e in failed} == {fix, "tick"} and all(e["agent"] == "gs" for e in failed)
    assert {e["exception"] for e in failed} == {"RuntimeError", "ZeroDivisionError"}
    assert sum(1 for m in answers if m.t > failed[0]["t"]) > 10
    assert reason == f"game ended: enough; agent failures: gs {faulty.raised}"
    assert agent_failures(tmp_path / "run" / "peers") == {"gs": faulty.raised}


def test_what_arrives_while_the_guidance_warms_up_waits_for_it_and_is_handled_in_order(tmp_path):
    """The warm-up runs off the loop and calls the guidance itself: an
    agent handling a fix on the loop meanwhile would run beside it, and
    would wait out the interpreter the warm-up holds on the clock its guard
    times. The fixes that reach the peer while it warms up reach its agent
    only once the warm-up has ended, every one of them, in order."""
    scenario = load_scenario(write_scenario(tmp_path, netem="ideal"))
    game = scenario.name
    players = build_cast(scenario, load_profile("ideal"), 0, people=[], ground=True)
    fix = keys.fix(game, "attacker")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    handled: list[tuple[float, int]] = []  # (when, seq) of each attacker fix the agent handled
    reached: list[int] = []  # seqs of the attacker fixes that reached the peer's session while it warmed up
    warming: list[float] = []  # when the warm-up began and ended
    published = threading.Event()

    class Timed(Faulty):
        def handle(self, key, message, now):
            if key == fix:
                handled.append((time.monotonic(), message.seq))
            return super().handle(key, message, now)

    def warm_up():
        warming.append(time.monotonic())
        players.warm_up()
        while len(reached) < 5 and not published.is_set():
            time.sleep(0.01)
        warming.append(time.monotonic())

    def play(player):
        """The attacker reports until the peer is up, then the game ends."""
        seq = 0
        while not player.alive(keys.every(game, "alive")) and seq < 600:
            seq += 1
            lat, lon = scenario.map.to_geodetic(25.0, 22.0)
            player.put(fix, encode(Fix(agent="attacker", seq=seq, t=time.time(), lat=lat, lon=lon)), reliable=False)
            time.sleep(0.05)
        published.set()
        player.put(keys.state(game), encode(GameState(seq=1, t=time.time(), phase="ended", reason="enough")))

    with (
        ZenohSession("gs", config(listen=[endpoint])) as session,
        ZenohSession("player", config(connect=[endpoint])) as player,
        closing(EventLog(tmp_path / "run" / "peers" / "gs.jsonl")) as record,
    ):
        session.subscribe(fix, lambda k, p, s: reached.append(decode(p, k).seq) if len(warming) == 1 else None)
        players_thread = threading.Thread(target=play, args=(player,))
        players_thread.start()
        reason = asyncio.run(run_peer([Timed(players.guidance)], session, game, record=record, warm_up=warm_up))
        players_thread.join()
    assert reason == "game ended: enough"
    assert len(reached) >= 5, "the attacker's fixes never reached the warming peer"
    ended = warming[1]
    assert all(when > ended for when, _ in handled), [when - ended for when, _ in handled if when <= ended]
    seqs = [seq for _, seq in handled]
    assert seqs == sorted(seqs) and set(reached) <= set(seqs), (reached, seqs)


def test_a_client_whose_router_is_not_there_says_so_in_one_sentence(tmp_path, env):
    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nothing listens there
    command = ["peer", "walker", "--scenario", str(write_scenario(tmp_path)), "--id", "attacker"]
    done = subprocess.run(
        [sys.executable, "-m", "bearcat", *command, "--mode", "client", "--connect", endpoint],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr.splitlines() == [
        f"bearcat: error: session 'attacker' could not connect to {endpoint}: "
        "nothing answered there (Connection refused)"
    ]


@pytest.mark.parametrize("sent", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_ctrl_c_or_sigterm_stops_every_peer(tmp_path, sent):
    """The signal only sets a flag that the launcher looks at between its
    polls, so wherever it lands, the run ends at a known point: the peers
    stopped, the outcome kept, and the moment it was heard recorded."""
    launcher, out, _path = start_run(tmp_path, time_limit=60.0, netem="ideal")
    try:
        assert wait_for(lambda: game_started(out), 120), "the game never started"
        sent_at = time.time()
        launcher.send_signal(sent)
        output, _ = launcher.communicate(timeout=60)
    finally:
        if launcher.poll() is None:
            launcher.kill()
    outcome = json.loads((out / "outcome.json").read_text())
    heard = [(e["signal"], e["t"] - sent_at) for e in read_events(out / "events.jsonl") if e["event"] == "interrupted"]
    assert outcome["reason"] == "interrupted" and launcher.returncode == 0, (outcome, heard, output)
    assert len(heard) == 1 and heard[0][0] == sent.name and heard[0][1] >= 0, heard
    assert wait_for(lambda: peers_of(out) == [], 10)


def test_peers_die_with_a_launcher_killed_by_sigkill(tmp_path):
    """A launcher that cannot clean up (SIGKILL) still takes its peers with it:
    each is started with the parent-death signal."""
    from bearcat.suites.checker import check_run

    launcher, out, _path = start_run(tmp_path, time_limit=60.0, netem="ideal")
    try:
        assert wait_for(lambda: game_started(out), 120), "the game never started"
        assert len(peers_of(out)) == 3
        assert sorted(p.pid for p in processes.recorded(out) if processes.running(p)) == sorted(peers_of(out))
        launcher.kill()
        launcher.communicate(timeout=10)
    finally:
        if launcher.poll() is None:
            launcher.kill()
    assert wait_for(lambda: peers_of(out) == [], 10)
    # What the launcher recorded outlives it: the checker knows the run's
    # processes, and finds none left once they have finished dying (a killed
    # process drops its command line before it exits).
    assert sorted(p.name for p in processes.recorded(out)) == ["attacker", "defender", "gs"]
    assert wait_for(lambda: {f.name: f.held for f in check_run(out)}["leftovers"] is True, 10)


def test_a_walker_whose_ground_station_is_gone_for_a_lease_stops_by_itself_saying_why(tmp_path, env):
    """Peers started by hand, with no launcher to stop them: the ground
    station is killed, and the walker, with nobody to play for, leaves once
    the lease is over."""
    path = write_scenario(tmp_path, time_limit=120.0, netem="ideal", lease=3.0)
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    with ZenohSession("router", config(listen=[endpoint], mode="router")) as router:
        common = ("--scenario", str(path), "--connect", endpoint, "--mode", "client")
        gs = subprocess.Popen([sys.executable, "-m", "bearcat", "peer", "ground-station", *common], env=env)
        walker = subprocess.Popen(
            [sys.executable, "-m", "bearcat", "peer", "walker", "--id", "attacker", *common],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        try:
            both = (keys.alive("test-game", "ground-station", "gs"), keys.alive("test-game", "walker", "attacker"))
            assert wait_for(lambda: all(router.alive(k, timeout=0.5) for k in both), 120), "the peers never came up"
            gs.kill()
            gs.wait()
            killed = time.monotonic()
            output, _ = walker.communicate(timeout=30)
            assert 3.0 <= time.monotonic() - killed < 3.0 + 5.0
            assert walker.returncode == 0 and "the ground station has been gone for 3 s" in output, output
        finally:
            for p in (gs, walker):
                if p.poll() is None:
                    p.kill()
                    p.wait()


def test_a_peer_started_elsewhere_fetches_the_scenario_and_map_from_the_ground_station(tmp_path):
    from bearcat.runtime.live import fetch_scenario

    plan, faults = (
        tmp_path / "plan.toml",
        parse_faults([{"kind": "degrade", "target": "attacker", "profile": "3g", "at": 50.0, "duration": 1.0}]),
    )
    write_faults(plan, faults)
    out = tmp_path / "run"
    launcher = start_launcher(write_scenario(tmp_path, time_limit=60.0, netem="ideal"), out, "--faults", str(plan))
    try:
        assert wait_for(lambda: game_started(out), 120), "the game never started"
        endpoint = json.loads((out / "endpoint.json").read_text())["endpoint"]
        scenario = fetch_scenario("test-game", [endpoint])
        assert scenario.name == "test-game" and scenario.map.bounds == (0.0, 0.0, 50.0, 50.0)
        assert scenario.ids == ["attacker", "defender"] and scenario.map.region("home")
        assert scenario.faults == faults  # the run's plan, which such a peer applies where it falls on it
        launcher.send_signal(signal.SIGINT)
        try:
            launcher.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            logs = {p.name: p.read_text()[-300:] for p in (out / "peers").glob("*.log")}
            pytest.fail(f"the launcher did not end within 120 s of SIGINT; its peers said {logs}")
    finally:
        if launcher.poll() is None:
            launcher.kill()


def test_an_agent_named_to_join_by_hand_is_waited_for_and_plays(tmp_path, env):
    """``bearcat run --joins defender`` starts no walker for the defender:
    it prints the command, waits for the peer, and plays with it."""
    path = write_scenario(tmp_path, time_limit=6.0, netem="ideal")
    out = tmp_path / "run"
    launcher = start_launcher(path, out, "--joins", "defender")
    person = None
    try:
        command = printed_command(launcher, "bearcat peer walker")
        assert command[command.index("--id") + 1] == "defender"
        assert wait_for(lambda: (out / "peers" / "gs.log").exists(), 60)
        time.sleep(3.0)
        assert not game_started(out), "the game started without the defender"
        joined = time.time()
        person = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, env=env)
        output, _ = launcher.communicate(timeout=180)
        assert person.wait(timeout=30) == 0
    finally:
        for p in (launcher, person):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
    assert launcher.returncode == 0, output
    outcome = json.loads((out / "outcome.json").read_text())
    assert outcome["ended"] and "defender" not in outcome["peers"] and "attacker" in outcome["peers"], outcome
    events = read_events(out / "events.jsonl")
    started = min(e["t"] for e in events if e["event"] == "sent" and e["message"].get("phase") == "running")
    fixes = [e["t"] for e in events if e["event"] == "sent" and e["key"] == keys.fix("test-game", "defender")]
    assert joined < started and fixes and fixes[0] > joined


async def _page_sends_fix(url: str, fix: dict) -> None:
    """What a phone's browser does once the page is open: connect its socket and send a fix."""
    base, token = url.split("?")
    async with (
        aiohttp.ClientSession(connector=aiohttp.TCPConnector(ssl=False)) as http,
        http.ws_connect(base + "ws?" + token) as ws,
    ):
        await ws.receive_json()  # the map
        await ws.send_str(json.dumps({"type": "fix", **fix}))
        await asyncio.sleep(1.0)


def test_a_phone_page_served_by_hand_joins_a_launched_game(tmp_path, env):
    """``bearcat run --phone attacker --joins attacker`` serves no page of
    its own: it prints the ``bearcat phone`` command, whose page (here on a
    port and with a token of the user's choosing) joins the game on the
    phone's first fix, and the referee judges on fixes."""
    path = write_scenario(tmp_path, time_limit=5.0, netem="ideal")
    scenario = load_scenario(path)
    out = tmp_path / "run"
    (tmp_path / "token").write_text("the-attacker-s-own\n")
    launcher = start_launcher(path, out, "--phone", "attacker", "--joins", "attacker")
    bridge = None
    try:
        command = printed_command(launcher, " phone --connect")
        assert command[command.index("--id") + 1] == "attacker"
        command += ["--listen", f"127.0.0.1:{free_port()}", "--token-file", str(tmp_path / "token")]
        bridge = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        url = bridge.stdout.readline().split()[1]
        assert "the-attacker-s-own" in url, url
        lat, lon = scenario.map.to_geodetic(25.0, 22.0)
        deadline = time.monotonic() + 60
        while not game_started(out):
            assert time.monotonic() < deadline, "the game never started"
            try:  # the page is served once the bridge has the map
                asyncio.run(_page_sends_fix(url, {"lat": lat, "lon": lon, "accuracy": 5.0, "age": 200.0}))
            except aiohttp.ClientConnectorError:
                time.sleep(0.2)
        output, _ = launcher.communicate(timeout=180)
        bridge.wait(timeout=30)
    finally:
        for p in (launcher, bridge):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
    assert launcher.returncode == 0 and "plays from a phone: open" not in output, output
    outcome = json.loads((out / "outcome.json").read_text())
    assert outcome["ended"] and "attacker" not in outcome["peers"], outcome
    events = read_events(out / "events.jsonl")
    states = [e["message"] for e in events if e["event"] == "sent" and e["message"]["type"] == "state"]
    assert states and all(s["judged_on"] == "fixes" for s in states)


def test_a_person_at_a_terminal_drives_a_keyboard_walker(tmp_path, env):
    """The launcher waits for the keyboard agent and prints the command; run
    in a real pseudo-terminal, its keys steer the walker (d: east, w:
    north, space: stop), as a person's would. Each key is pressed once the
    truth shows the last one obeyed, so a loaded machine slows the test but
    cannot fail it; the walker keeps its heading exactly (no heading error),
    so the directions are the keys'."""
    import pty

    from bearcat.maps import load_map

    path = write_scenario(
        tmp_path,
        time_limit=600.0,
        netem="ideal",
        attacker=(10.0, 10.0),
        defender=(40.0, 30.0),
        attacker_behaviour="keyboard",
        defender_behaviour="follow-guidance",
    )
    path.write_text(path.read_text().replace('behaviour = "keyboard"', 'behaviour = "keyboard"\nheading_error = 0.0'))
    out = tmp_path / "run"
    launcher = start_launcher(path, out)
    field = load_map("field-50")

    def track() -> list[tuple[float, tuple[float, float]]]:
        return [
            (e["t"], field.to_local(e["message"]["lat"], e["message"]["lon"]))
            for e in read_events(out / "events.jsonl")
            if e["event"] == "sent" and e["message"].get("type") == "truth" and e["message"]["agent"] == "attacker"
        ]

    def since(t: float) -> list[tuple[float, float]]:
        return [p for when, p in track() if when >= t]

    def still(t: float) -> bool:
        """Whether the walker has stood still for a second, after ``t``."""
        points = [(when, p) for when, p in track() if when >= t]
        last = points[-1][0] if points else t
        held = [p for when, p in points if when >= last - 1.0]
        return last - t >= 1.0 and max(math.dist(held[0], p) for p in held) < 0.05

    person = None
    try:
        command = None
        for line in launcher.stdout:
            if "bearcat peer walker" in line:
                command = line.split()
                break
        assert command is not None, "the launcher did not print the keyboard peer's command"
        master, slave = pty.openpty()
        person = subprocess.Popen(command, stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True)
        os.close(slave)
        assert wait_for(lambda: game_started(out), 120), "the game never started"
        legs = []
        for key in (b"d", b"w"):
            t = time.time()
            start = track()[-1][1]
            os.write(master, key)
            # A key the walker does not obey leaves this wait to the game's time limit.
            assert wait_for(lambda s=start, t=t: any(math.dist(s, p) > 5.0 for p in since(t)), 600.0), key
            t = time.time()
            os.write(master, b" ")
            assert wait_for(lambda t=t: still(t), 600.0), "the walker did not stop"
            legs.append((start, since(t)[-1]))
        launcher.send_signal(signal.SIGINT)
        launcher.communicate(timeout=60)
        person.wait(timeout=30)
        os.close(master)
    finally:
        for p in (launcher, person):
            if p is not None and p.poll() is None:
                p.kill()
    (east_from, east_to), (north_from, north_to) = legs
    assert east_to[0] - east_from[0] > 5.0 and abs(east_to[1] - east_from[1]) < 0.05
    assert north_to[1] - north_from[1] > 5.0 and abs(north_to[0] - north_from[0]) < 0.05


@pytest.mark.slow  # solves the fake-out's 45^4 game unless an earlier test did
def test_a_person_plays_the_fake_out_defender_and_the_game_joins_the_study(tmp_path, env):
    """``bearcat study fake-out --human defender`` prints the keyboard peer's
    command, plays the game live with the person's keys (here: walk south,
    out of the attacker's way) and appends it to the study's results under
    the defender "human", where the table shows it."""
    import pty

    env = dict(env, BEARCAT_CACHE_DIR=os.environ["BEARCAT_CACHE_DIR"])  # the session's: its 45^4 solve is shared
    out = tmp_path / "study"
    study = subprocess.Popen(
        [sys.executable, "-m", "bearcat", "study", "fake-out", "--human", "defender", "--trials", "1", "--out", out],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    person = None
    try:
        command, printed = None, []
        for line in study.stdout:
            printed.append(line)
            if "bearcat peer walker" in line:
                command = line.split()
                break
        assert command is not None, "".join(printed)
        master, slave = pty.openpty()
        person = subprocess.Popen(command, stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True)
        os.close(slave)
        assert wait_for(lambda: game_started(out / "human" / "seed-0"), 120), "the game never started"
        os.write(master, b"s")
        rest, _ = study.communicate(timeout=120)
        person.wait(timeout=30)
        os.close(master)
    finally:
        for p in (study, person):
            if p is not None and p.poll() is None:
                p.kill()
    assert study.returncode == 0, rest
    (row,) = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    assert row["labels"]["defender"] == "human" and row["winner"] in ("attacker", "defender") and row["seed"] == 0
    assert "a person as the defender, phones at 1 Hz: attacker wins" in rest and (out / "fake-out.png").exists()
    assert (out / "human" / "seed-0" / "events.jsonl").exists()


PROVISIONAL = """
[scenario]
name = "provisional"
map = "field-50"
game = "ctf"
time_limit = 900.0  # the test ends the game once the 25-point sets, solved on idle processors only, are taken up
netem = "ideal"

[rules]
capture_radius = 2.5
stages = "return"
grid = 25
provisional_grid = 21

[[agent]]
id = "attacker"
team = "attacker"
start = [10.0, 8.0]
speed = 3.0
behaviour = "waypoints"
aided = true
options = { points = [[40.0, 8.0], [10.0, 8.0]], loop = true }

[[agent]]
id = "defender"
team = "defender"
start = [10.0, 38.0]
speed = 3.0
behaviour = "waypoints"
aided = true
options = { points = [[40.0, 38.0], [10.0, 38.0]], loop = true }
"""


def test_a_run_whose_sets_are_not_cached_starts_on_provisional_ones_and_takes_its_own_up(tmp_path, monkeypatch):
    """The game starts on the 21-point sets while the 25-point ones solve
    behind it (held here until the game is on, so the order is certain);
    the ground station takes those up mid-game, guides from them, and they
    stay in the cache. The solve gives way to every other process (nice
    19), so however long it takes on a loaded machine, the game goes on
    until the test has seen guidance from the sets taken up, then ends it
    with Ctrl-C."""
    from bearcat.agents.ground_station.ctf_cache import cached, turn
    from bearcat.scenarios.cast import awaited_sets

    monkeypatch.setenv("BEARCAT_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "game.toml"
    path.write_text(PROVISIONAL)
    awaited = awaited_sets(load_scenario(path))
    out = tmp_path / "run"
    gs_log = out / "peers" / "gs.jsonl"

    def guided_from_its_own() -> bool:
        record = read_events(gs_log) if gs_log.exists() else []
        taken = [e["t"] for e in record if e["event"] == "sets" and e["grid"] == 25]
        return bool(taken) and any(e["t"] > taken[0] and "/guidance/" in e.get("key", "") for e in record)

    with turn(awaited.game, awaited.stages):
        launcher = start_launcher(path, out)
        started = wait_for(lambda: game_started(out), 120)
    try:
        assert started, "the game never started"
        assert wait_for(guided_from_its_own, 900.0), "the 25-point sets were never taken up"  # the game's limit
        launcher.send_signal(signal.SIGINT)
        output, _ = launcher.communicate(timeout=180)
    finally:
        if launcher.poll() is None:
            launcher.kill()
    assert "guidance starts on the 21-point sets and takes up the 25-point sets" in output
    record = read_events(gs_log)
    notes = [(e["grid"], e["awaited"]) for e in record if e["event"] == "sets"]
    assert notes == [(21, 25), (25, None)], notes
    assert cached(awaited.game, awaited.stages) is not None
    assert peers_of(out) == []
