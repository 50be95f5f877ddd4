"""The simulation runtime end to end: a finished game with a winner the rules
allow, the same seed giving the same event log line for line, the network
profile showing in what the log records, an agent's exceptions recorded and
counted while the game goes on, and the referee's rules on their own."""

import itertools
import json

import numpy as np
import pytest
import shapely

from bearcat.agents.ground_station.event_log import read_events
from bearcat.agents.ground_station.referee import Contest, Referee
from bearcat.bus import keys
from bearcat.bus.messages import Control, Truth
from bearcat.maps import load_map
from bearcat.netem.profiles import load_profile
from bearcat.runtime.simulate import simulate
from bearcat.scenarios.cast import build_cast
from bearcat.scenarios.schema import load_scenario
from tests.support.faulty import Faulty
from tests.support.scenario_files import write_scenario


@pytest.fixture(autouse=True)
def cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("BEARCAT_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "cache"))


def play(tmp_path, seed=0, netem=None, name="run", transport=None, **kw):
    scenario = load_scenario(write_scenario(tmp_path, **kw))
    events = tmp_path / name / "events.jsonl"
    return simulate(scenario, seed=seed, netem=netem, transport=transport, events=events), read_events(events)


def test_a_game_finishes_with_a_winner_and_a_reason_the_rules_give(tmp_path):
    outcome, events = play(tmp_path)
    assert outcome.ended and outcome.winner in ("attacker", "defender")
    assert any(word in outcome.reason for word in ("captured", "returned the flag", "time limit"))
    assert events[-1]["event"] == "outcome" and events[-1]["winner"] == outcome.winner
    states = [e["message"] for e in events if e["event"] == "sent" and e["message"]["type"] == "state"]
    assert next(s["phase"] for s in states) == "waiting" and states[-1]["phase"] == "ended"
    assert states[-1]["elapsed"] == pytest.approx(outcome.elapsed)
    assert outcome.failures == {} and not [e for e in events if e["event"] == "failed"]


def test_the_same_seed_gives_the_same_event_log_and_another_seed_does_not(tmp_path):
    play(tmp_path, seed=5, name="a")
    play(tmp_path, seed=5, name="b")
    play(tmp_path, seed=6, name="c")
    a, b, c = ((tmp_path / n / "events.jsonl").read_bytes() for n in "abc")
    assert a == b
    assert a != c


def test_a_game_without_an_event_log_counts_what_one_with_a_log_records(tmp_path):
    scenario = load_scenario(write_scenario(tmp_path))
    logged, events = (
        simulate(scenario, seed=3, events=tmp_path / "events.jsonl"),
        read_events(tmp_path / "events.jsonl"),
    )
    unlogged = simulate(scenario, seed=3)
    assert unlogged == logged
    kinds = [e["event"] if e["event"] != "impaired" else f"impaired:{e['action']}" for e in events]
    assert logged.counts == {kind: kinds.count(kind) for kind in set(kinds) if kind != "outcome"}


def play_with_a_faulty_ground_station(tmp_path, name, seed=2):
    """A game whose guidance service raises on every fourth fix of the
    attacker and on every seventh tick."""
    scenario = load_scenario(write_scenario(tmp_path))
    players = build_cast(scenario, load_profile(scenario.netem), seed)
    fix = keys.fix(scenario.name, "attacker")
    faulty = Faulty(players.guidance, fails_on=lambda key, message: key == fix and message.seq % 4 == 0, every=7)
    players.guidance = faulty
    events = tmp_path / name / "events.jsonl"
    return simulate(scenario, seed=seed, events=events, players=players), faulty, read_events(events)


def test_an_agent_that_raises_is_recorded_and_counted_and_the_game_goes_on(tmp_path):
    outcome, faulty, events = play_with_a_faulty_ground_station(tmp_path, "a")
    assert outcome.ended and outcome.winner in ("attacker", "defender") and events[-1]["event"] == "outcome"
    failed = [e for e in events if e["event"] == "failed"]
    assert faulty.raised > 0 and len(failed) == faulty.raised
    assert outcome.failures == {"gs": faulty.raised} == events[-1]["failures"]
    assert outcome.counts["failed"] == faulty.raised
    on_fixes = [e for e in failed if e["key"] != "tick"]
    on_ticks = [e for e in failed if e["key"] == "tick"]
    assert on_fixes and on_ticks and all(e["agent"] == "gs" for e in failed)
    assert all(e["key"] == keys.fix("test-game", "attacker") and e["exception"] == "RuntimeError" for e in on_fixes)
    assert all("no answer to Fix seq" in e["reason"] for e in on_fixes)
    assert all(e["exception"] == "ZeroDivisionError" and "divided by zero" in e["reason"] for e in on_ticks)
    # The service goes on answering after its first failure, on ticks and on fixes.
    guidance = [e for e in events if e["event"] == "sent" and "/guidance/" in e["key"]]
    assert sum(1 for e in guidance if e["t"] > failed[0]["t"]) > 10
    # Failures are as deterministic as the rest of the run.
    play_with_a_faulty_ground_station(tmp_path, "b")
    assert (tmp_path / "a" / "events.jsonl").read_bytes() == (tmp_path / "b" / "events.jsonl").read_bytes()


def test_guidance_comes_from_fixes_the_network_delivered(tmp_path):
    _outcome, events = play(tmp_path, netem="3g-degraded", seed=1, transport="udp")
    impaired = [e for e in events if e["event"] == "impaired"]
    actions = {e["action"] for e in impaired}
    assert "dropped" in actions and "delivered" in actions
    # Nothing on a truth or control key is ever impaired.
    assert not [e for e in impaired if "/truth/" in e["key"] or e["key"].endswith("/control")]
    # Every fix the ground station received was sent before it arrived, and
    # the lost ones (by seq) are exactly those the shim dropped on that link.
    sent = {(e["key"], e["message"]["seq"]): e["t"] for e in events if e["event"] == "sent" and "/fix/" in e["key"]}
    got = [
        (e["key"], e["seq"], e["t"])
        for e in events
        if e["event"] == "received" and e["receiver"] == "gs" and "/fix/" in e["key"]
    ]
    assert got and all(t >= sent[(k, s)] for k, s, t in got)
    dropped = sum(1 for e in impaired if e["action"] == "dropped" and "/fix/" in e["key"] and e["receiver"] == "gs")
    duplicated = sum(
        1 for e in impaired if e["action"] == "duplicated" and "/fix/" in e["key"] and e["receiver"] == "gs"
    )
    ended = max(e["t"] for e in events if e["event"] != "outcome")
    in_time = [k for k, t in sent.items() if t < ended - 3.0]  # sent early enough to have arrived
    received = {(k, s) for k, s, _ in got}
    assert len(in_time) - sum(1 for k in in_time if k in received) <= dropped
    assert len(got) - len(received) == duplicated


def test_ideal_network_delivers_every_fix_at_once(tmp_path):
    _, events = play(tmp_path, netem="ideal")
    sent = {(e["key"], e["message"]["seq"]): e["t"] for e in events if e["event"] == "sent" and "/fix/" in e["key"]}
    got = {
        (e["key"], e["seq"]): e["t"]
        for e in events
        if e["event"] == "received" and e["receiver"] == "gs" and "/fix/" in e["key"]
    }
    assert got and set(got) == set(sent) and all(got[k] == sent[k] for k in got)
    assert not [e for e in events if e["event"] == "impaired"]


def test_an_aided_defender_that_starts_winning_keeps_the_attacker_out(tmp_path):
    outcome, _ = play(
        tmp_path, defender_behaviour="follow-guidance", defender_aided=True, netem="ideal", time_limit=20.0
    )
    assert outcome.winner == "defender"


def test_an_unopposed_direct_attacker_returns_the_flag(tmp_path):
    # The defender starts far behind the attacker, who just runs home.
    outcome, _ = play(tmp_path, attacker_behaviour="direct", attacker=(25.0, 30.0), defender=(45.0, 2.0), netem="ideal")
    assert outcome.winner == "attacker" and "returned the flag" in outcome.reason
    assert outcome.elapsed == pytest.approx((45.0 - 30.0) / 3.0, abs=1.5)


# ---------------------------------------------------------------------- referee


def referee(**kw):
    field = load_map("field-50")
    home = field.region("home").geometry
    flag = field.region("flag").geometry
    contest = Contest(
        runners=("a",),
        chasers=("d",),
        capture_radius=2.5,
        time_limit=kw.get("limit", 60.0),
        teams=("attacker", "defender"),
        targets=(("home", home),),
        forbidden=(("flag", flag), ("return", home)),
        flag_taken=True,
    )
    return Referee("g", field, contest), field


def truth(field, agent, x, y, t):
    lat, lon = field.to_geodetic(x, y)
    return keys.truth("g", agent), Truth(agent=agent, t=t, lat=lat, lon=lon)


def run_referee(ref, field, tracks, dt=0.1):
    """Feed positions (agent -> list of (x, y) per tick) and tick; the last state."""
    ref.handle(keys.control("g"), Control(t=0.0, command="start"), 0.0)
    last = None
    for k in range(len(next(iter(tracks.values())))):
        t = (k + 1) * dt
        for agent, track in tracks.items():
            ref.handle(*truth(field, agent, *track[k], t), t)
        for send in ref.tick(t):
            last = send.message
        if last is not None and last.phase == "ended":
            break
    return last


def test_agents_that_pass_through_each_other_within_a_step_are_captured():
    ref, field = referee()
    # Head-on at 30 m/s each: 6 m apart, then 6 m apart the other way, in one step.
    state = run_referee(ref, field, {"a": [(22.0, 20.0), (28.0, 20.0)], "d": [(28.0, 20.0), (22.0, 20.0)]})
    assert state.phase == "ended" and state.winner == "defender" and state.captured == ["a"]


def test_the_attacker_wins_by_reaching_home_and_the_defender_forfeits_by_entering_it():
    ref, field = referee()
    state = run_referee(ref, field, {"a": [(10.0, 40.0), (10.0, 46.0)], "d": [(40.0, 20.0)] * 2})
    assert state.winner == "attacker" and "returned the flag" in state.reason
    ref, field = referee()
    state = run_referee(ref, field, {"a": [(10.0, 20.0)] * 2, "d": [(40.0, 44.0), (40.0, 46.0)]})
    assert state.winner == "attacker" and "entered the return region" in state.reason


def test_time_runs_out_for_the_attacker_and_a_vanished_peer_ends_the_game():
    ref, field = referee(limit=1.0)
    state = run_referee(ref, field, {"a": [(10.0, 20.0)] * 20, "d": [(40.0, 20.0)] * 20})
    assert state.winner == "defender" and "time limit" in state.reason and state.elapsed == pytest.approx(1.0)
    ref, field = referee()
    run_referee(ref, field, {"a": [(10.0, 20.0)] * 2, "d": [(40.0, 20.0)] * 2})
    assert ref.peer(keys.alive("g", "walker", "d"), False, 0.5) == []
    ref.tick(0.5 + ref.rejoin - 0.1)
    assert ref.phase == "running"  # it may yet rejoin
    (send,) = ref.tick(0.5 + ref.rejoin)
    assert send.message.phase == "ended" and send.message.winner is None and "walker d is gone" in send.message.reason


def test_a_player_that_rejoins_in_time_plays_on_and_captures_nobody_while_away():
    ref, field = referee()
    run_referee(ref, field, {"a": [(10.0, 20.0)] * 2, "d": [(40.0, 20.0)] * 2})
    ref.peer(keys.alive("g", "walker", "d"), False, 0.3)
    ref.handle(*truth(field, "a", 40.0, 21.0, 0.4), 0.4)  # right by the defender's last fix
    ref.tick(0.4)
    assert ref.captured == [] and ref.phase == "running"
    ref.peer(keys.alive("g", "walker", "d"), True, 0.5)
    ref.tick(0.5)
    assert ref.captured == ["a"]  # back, and within reach


def test_a_restarted_referee_resumes_the_game_clock_the_flag_and_the_captures():
    ref, field = referee()
    run_referee(ref, field, {"a": [(10.0, 20.0)] * 5, "d": [(40.0, 20.0)] * 5})
    (last,) = ref.tick(3.0)
    again, _ = referee()
    again.resume(last.message)
    (state,) = again.tick(10.0)
    assert state.message.phase == "running" and state.message.elapsed == pytest.approx(10.0)
    assert state.message.seq == last.message.seq + 1 and state.message.flag_holder == "a"


def test_outcome_json_of_the_cli_matches_the_event_log(tmp_path):
    from bearcat.cli.main import main

    path = write_scenario(tmp_path)
    assert main(["simulate", str(path), "--trials", "2", "--seed", "4", "--out", str(tmp_path / "out"), "--json"]) == 0
    for seed in (4, 5):
        outcome = json.loads((tmp_path / "out" / f"seed-{seed}" / "outcome.json").read_text())
        last = read_events(tmp_path / "out" / f"seed-{seed}" / "events.jsonl")[-1]
        assert (outcome["winner"], outcome["reason"]) == (last["winner"], last["reason"])
        assert (tmp_path / "out" / f"seed-{seed}" / "recording.rrd").stat().st_size > 1000


def test_walkers_never_enter_buildings_or_forbidden_regions():
    from bearcat.agents.human.walker import Walker

    campus = load_map("campus-200")
    hall = campus.obstacles[0]
    rng = np.random.default_rng(0)
    home = campus.region("home").geometry
    w = Walker(campus, (100.0, 70.0), speed=5.0, heading_error=20.0, keep_out=home, rng=rng)
    w.intend(0.0, (0.0, 1.0))  # straight north, into the hall and then home
    for k in range(400):
        w.step(k * 0.1, 0.1)
        p = shapely.Point(w.position)
        assert not hall.contains(p) and not home.contains(p)
    assert w.position[1] < 165.0


def test_a_walker_turns_only_after_its_reaction_time():
    from bearcat.agents.human.walker import Walker

    w = Walker(load_map("field-50"), (25.0, 25.0), speed=1.0, reaction=0.5, rng=np.random.default_rng(0))
    w.intend(0.0, (1.0, 0.0))
    positions = []
    for k in range(10):
        positions.append(w.step(k * 0.1, 0.1).copy())
    moved = [float(np.hypot(*(b - a))) for a, b in itertools.pairwise(positions)]
    assert positions[4][0] == pytest.approx(25.0) and moved[-1] == pytest.approx(0.1)


def test_aided_pursuers_capture_the_evader_and_see_their_boundary(tmp_path):
    from dataclasses import replace

    scenario = replace(load_scenario("pursuit-field"), time_limit=60.0)
    events = tmp_path / "events.jsonl"
    outcome = simulate(scenario, netem="ideal", events=events)
    assert outcome.winner == "pursuer" and outcome.captured == ["evader"]
    shown = [e["message"] for e in read_events(events) if e["event"] == "sent" and "/guidance/pursuer-" in e["key"]]
    answered = [m for m in shown if m.get("heading") is not None]
    assert len(answered) > 0.9 * len(shown)
    # The evader's cell is shown, and its area only shrinks as the chase goes on.
    areas = [m["value"] for m in answered if m["agent"] == "pursuer-1"]
    assert areas[0] > 1000 and areas[-1] < 0.2 * areas[0]
    # Late in the chase the evader's cell is bounded by some pursuer's line of
    # control at every moment (a pursuer behind another has none, 5.3.1).
    late = [m for m in answered if m["t"] >= answered[len(answered) // 2]["t"]]
    bounded = {m["t"] for m in late if m["boundary"]}
    assert bounded == {m["t"] for m in late}


def test_against_real_players_the_referee_judges_on_fixes_and_says_so():
    ref, field = referee()
    fixes_ref = Referee("g", field, ref.contest, on_truth=False)
    assert keys.every("g", "fix") in fixes_ref.subscriptions and keys.every("g", "truth") not in fixes_ref.subscriptions
    (send,) = fixes_ref.start(0.0)
    assert send.message.judged_on == "fixes"


def test_keys_steer_a_keyboard_walker_and_space_stops_it():
    from bearcat.agents.human.behaviours import Keyboard
    from bearcat.agents.options import NoOptions

    keyboard = Keyboard(NoOptions(), np.random.default_rng(0))
    assert keyboard.decide(0.0, None, None, None) is None
    assert keyboard.press("up") and keyboard.decide(0.0, None, None, None).tolist() == [0.0, 1.0]
    assert keyboard.press("a") and keyboard.decide(0.0, None, None, None).tolist() == [-1.0, 0.0]
    assert not keyboard.press("z") and keyboard.decide(0.0, None, None, None).tolist() == [-1.0, 0.0]
    assert keyboard.press("space") and keyboard.decide(0.0, None, None, None) is None


def test_over_tcp_no_fix_is_lost_but_some_arrive_late_in_bursts(tmp_path):
    """The same game with fixes over tcp/: the shim's TCP stream loses nothing
    and holds what follows a loss, which then arrives in a burst."""
    _outcome, events = play(tmp_path, netem="3g-degraded", seed=1, transport="tcp")
    fixes = [e for e in events if e["event"] == "impaired" and "/fix/" in e["key"] and e["receiver"] == "gs"]
    assert fixes and not [e for e in fixes if e["action"] == "dropped"]
    late = [e for e in fixes if any(r.startswith("retransmitted") for r in e["reasons"])]
    assert late and min(e["delay"] for e in late) > 0.5
    arrivals = sorted(e["t"] + e["delay"] for e in fixes)
    assert sum(b - a < 0.002 for a, b in itertools.pairwise(arrivals)) > len(late)  # what waited came with it


def test_worst_case_guidance_sends_each_report_s_disk_and_the_recording_draws_them(tmp_path):
    """Each report's radius is at least the distance its agent could walk
    since the fix (3 m/s), the robust answers say when the plain one would
    differ, and the recording has the disks on the phone and beside the truth."""
    from bearcat.cli.main import main

    path = write_scenario(tmp_path, defender_behaviour="follow-guidance", defender_aided=True, method="worst-case")
    assert main(["simulate", str(path), "--seed", "4", "--out", str(tmp_path / "out")]) == 0
    run = tmp_path / "out" / "seed-4"
    guidance = [
        e["message"] for e in read_events(run / "events.jsonl") if e.get("message", {}).get("type") == "guidance"
    ]
    reports = [(m["t"], r) for m in guidance for r in m["reports"]]
    assert reports and all(r["radius"] >= 3.0 * (t - r["t"]) - 0.01 for t, r in reports)
    assert any(m.get("uncertain") for m in guidance)
    recording = (run / "recording.rrd").read_bytes()
    assert b"ground/uncertainty/attacker" in recording and b"phone/defender/disks" in recording
