"""Fault plans in simulation, and the run checker that judges the runs.

Each fault kind is applied to a real simulated game (codec, shim, agents),
and the test asserts what the fault must do to the recorded messages: what
a cut loses and holds, what a pause delays, what a lying GPS reports; then
the checker, reading only the run directory, says the invariants held. The
checker is shown to catch runs that break them too.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from bearcat.agents.ground_station.event_log import read_events
from bearcat.cli.main import main
from bearcat.runtime import processes
from bearcat.runtime.run_directory import fresh, write_scenario
from bearcat.runtime.simulate import simulate
from bearcat.scenarios.faults import FaultError, load_faults, parse_faults
from bearcat.scenarios.schema import ScenarioError, parse_scenario
from bearcat.suites.checker import check_run
from tests.support.scenario_files import scenario_text

LEASE = 3.0


def game(**kw):
    return parse_scenario(scenario_text(lease=LEASE, **kw), source="game.toml")


def play(tmp_path, plan, transport=None, seed=None, **kw):
    """Simulate the test game under ``plan`` into a run directory; (outcome, events, findings by name)."""
    scenario = game(**kw)
    run = tmp_path / "run"
    run.mkdir()
    write_scenario(run, scenario)
    outcome = simulate(scenario, faults=parse_faults(plan), events=run / "events.jsonl", transport=transport, seed=seed)
    (run / "outcome.json").write_text(json.dumps(asdict(outcome)))
    findings = {f.name: f for f in check_run(run)}
    return outcome, read_events(run / "events.jsonl"), findings


def held(findings) -> None:
    broken = [f"{f.name}: {f.evidence}" for f in findings.values() if f.held is False]
    assert not broken, broken


def sent(events, kind, agent=None):
    return [
        e
        for e in events
        if e["event"] == "sent" and f"/{kind}" in e["key"] and (agent is None or e["key"].endswith(f"/{agent}"))
    ]


# ---------------------------------------------------------------- plans


@pytest.mark.parametrize(
    ("plan", "said"),
    [
        ({"kind": "kil", "target": "attacker"}, "fault[0].kind: 'kil' is not one of 'kill', 'stop'"),
        ({"kind": "pause", "target": "attacker"}, "fault[0].duration: must be given, as a number in (0, 86400] s"),
        (
            {"kind": "kill", "target": "atacker"},
            "fault[0].target: there is no peer 'atacker'; the peers are gs, attacker, defender",
        ),
        (
            {"kind": "partition", "groups": [["attacker"], ["attacker", "gs"]]},
            "fault[0].groups: peer 'attacker' is in two groups",
        ),
        ({"kind": "gps", "target": "gs", "mode": "jump"}, "fault[0].target: 'gs' carries no phone"),
        (
            {"kind": "gps", "target": "attacker", "mode": "spoof"},
            "fault[0].position: a spoofed fix needs the [east, north]",
        ),
        (
            {"kind": "kill", "target": "gs", "after": "defender.goes"},
            "fault[0].after: agent defender never goes: its behaviour direct does not commit to a run",
        ),
        ({"kind": "kill", "target": "gs", "after": "lunch"}, "fault[0].after: 'lunch' is not an event"),
    ],
)
def test_a_bad_fault_is_one_sentence_naming_the_key(tmp_path, plan, said):
    text = scenario_text() + "\n[[fault]]\n" + "\n".join(f"{k} = {json.dumps(v)}" for k, v in plan.items()) + "\n"
    with pytest.raises(ScenarioError, match="^game.toml: " + _escape(said)):
        parse_scenario(text, source="game.toml")
    path = tmp_path / "plan.toml"
    path.write_text("[[fault]]\n" + "\n".join(f"{k} = {json.dumps(v)}" for k, v in plan.items()) + "\n")
    with pytest.raises(FaultError, match=f"^{_escape(str(path))}: " + _escape(said)):
        load_faults(path, game())


def _escape(text: str) -> str:
    import re

    return re.escape(text)


def test_simulate_refuses_what_it_cannot_apply_before_the_run(tmp_path, capsys):
    path = tmp_path / "game.toml"
    path.write_text(scenario_text())
    plan = tmp_path / "plan.toml"
    plan.write_text('[[fault]]\nkind = "cpu"\ntarget = "gs"\nshare = 0.2\nduration = 5.0\n')
    assert main(["simulate", str(path), "--faults", str(plan), "--out", str(tmp_path / "out")]) == 2
    assert "fault[0] (cpu) cannot be applied by simulate: in virtual time" in capsys.readouterr().err
    assert not any((tmp_path / "out").glob("seed-*/events.jsonl"))


@pytest.mark.parametrize(
    ("fault", "why"),
    [
        ('kind = "restart"', "no launcher holds its process to start it again"),
        ('kind = "cpu"\nduration = 4.0', "starving it takes a cgroup on its own machine"),
    ],
)
def test_a_run_refuses_what_a_peer_joined_by_hand_cannot_do_to_itself_before_anything_starts(
    tmp_path, capsys, fault, why
):
    """The launcher holds no process of an agent named with --joins: the
    peer kills, stops or pauses itself on the launcher's notice, but cannot
    start itself again or cap its own CPU. One sentence, and no run directory."""
    path = tmp_path / "game.toml"
    path.write_text(scenario_text())
    plan = tmp_path / "plan.toml"
    plan.write_text(f'[[fault]]\n{fault}\ntarget = "defender"\nat = 3.0\n')
    out = tmp_path / "out"
    assert main(["run", str(path), "--faults", str(plan), "--joins", "defender", "--out", str(out)]) == 2
    kind = fault.split('"')[1]
    said = capsys.readouterr().err
    assert f"fault[0] ({kind}) targets defender, whose peer is started by hand: {why}" in said
    assert "applies kill, stop, pause itself" in said
    assert not out.exists()


# ---------------------------------------------------------------- processes


def test_a_killed_walker_is_seen_gone_at_once_and_forfeits_after_the_lease(tmp_path):
    outcome, events, findings = play(tmp_path, [{"kind": "kill", "target": "defender", "at": 4.0}])
    gone = [e for e in events if e["event"] == "gone" and e["key"].endswith("/defender")]
    assert gone and gone[0]["t"] == pytest.approx(4.0)
    assert outcome.reason == "walker defender is gone" and outcome.elapsed == pytest.approx(4.0 + LEASE, abs=0.11)
    assert not [e for e in sent(events, "truth", "defender") if e["t"] > 4.0]  # a dead body reports nothing
    held(findings)
    assert "ended by fault[0] (kill defender" in findings["verdict"].evidence


def test_a_pause_within_the_lease_delays_what_the_peer_receives_and_loses_nothing(tmp_path):
    outcome, events, findings = play(tmp_path, [{"kind": "pause", "target": "gs", "at": 3.0, "duration": 2.0}])
    assert not [e for e in events if e["event"] == "gone"]
    to_gs = [e for e in events if e["event"] == "received" and e["receiver"] == "gs"]
    assert not [e for e in to_gs if 3.0 + 1e-9 < e["t"] < 5.0 - 1e-9]  # asleep
    woke = [e for e in to_gs if e["t"] == pytest.approx(5.0)]
    assert len(woke) >= 2 * 2 - 1  # what the two phones sent while it slept, at 1 Hz each
    assert not [e for e in sent(events, "guidance") if 3.0 + 1e-9 < e["t"] < 5.0 - 1e-9]
    assert outcome.ended
    held(findings)


def test_a_pause_past_the_lease_is_seen_at_the_lease_and_rejoins_on_waking(tmp_path):
    outcome, events, findings = play(tmp_path, [{"kind": "pause", "target": "attacker", "at": 2.0, "duration": 5.0}])
    seen = [(e["event"], e["t"]) for e in events if e["event"] in ("gone", "alive") and e["key"].endswith("/attacker")]
    assert seen == [("gone", pytest.approx(2.0 + LEASE)), ("alive", pytest.approx(7.0))]
    assert outcome.ended and "is gone" not in outcome.reason  # back within the lease the referee grants
    held(findings)


def test_a_restarted_walker_rejoins_where_it_stood_and_the_game_ends_with_a_verdict(tmp_path):
    outcome, events, findings = play(tmp_path, [{"kind": "restart", "target": "attacker", "at": 3.0, "duration": 1.0}])
    track = [(e["t"], e["message"]) for e in sent(events, "truth", "attacker")]
    before = [m for t, m in track if t <= 3.0][-1]
    after = next(m for t, m in track if t > 3.0)
    assert after["lat"] == pytest.approx(before["lat"], abs=1e-6) and after["lon"] == pytest.approx(
        before["lon"], abs=1e-6
    )
    assert outcome.ended and outcome.winner is not None
    held(findings)


def test_a_restarted_ground_station_resumes_the_game_clock_and_the_state_numbers(tmp_path):
    outcome, events, findings = play(tmp_path, [{"kind": "restart", "target": "gs", "at": 3.0, "duration": 2.0}])
    states = [e["message"] for e in sent(events, "state")]
    seqs = [s["seq"] for s in states]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    running = [(s["t"], s["elapsed"]) for s in states if s["phase"] == "running"]
    assert all(abs((t - e) - running[0][0] + running[0][1]) < 0.11 for t, e in running)  # one clock, never reset
    assert [t for t, _ in running if 3.0 < t < 5.0] == []  # nobody referees while it is down
    guidance = [(e["t"], e["message"]) for e in sent(events, "guidance")]
    assert [m["seq"] for _, m in guidance] == sorted({m["seq"] for _, m in guidance})  # one count, never reset
    shown = [{r["agent"] for r in m["reports"]} for t, m in guidance if t >= 5.0]
    assert shown and all(agents == {"attacker", "defender"} for agents in shown)  # the last fixes, remembered
    assert outcome.ended and outcome.winner is not None
    held(findings)


def test_a_stopped_ground_station_ends_the_run_naming_the_fault(tmp_path):
    outcome, _, findings = play(tmp_path, [{"kind": "stop", "target": "gs", "at": 2.0}])
    assert not outcome.ended and outcome.reason.startswith("the ground station is gone: fault[0] (stop gs")
    held(findings)


def test_a_plugins_fault_is_not_blamed_for_a_verdict_a_planned_fault_kept_from_the_game(tmp_path):
    """The plan stopped the ground station, so the run has no verdict and says why; whether a plug-in's
    overrun just before kept the game from one cannot be judged, and is not held against it."""
    play(tmp_path, [{"kind": "stop", "target": "gs", "at": 2.0}])
    overran = {"event": "plugin", "t": 1.9, "at": 1.9, "peer": "gs", "agent": "attacker", "plugin": "none"}
    overran |= {"fault": "overran", "detail": "took 819 ms, past its budget of 25 ms"}
    with (tmp_path / "run" / "events.jsonl").open("a") as f:
        f.write(json.dumps(overran) + "\n")
    findings = {f.name: f for f in check_run(tmp_path / "run")}
    assert findings["verdict"].held and findings["plugins"].held is None
    assert "because the ground station is gone: fault[0] (stop gs" in findings["plugins"].evidence


# ---------------------------------------------------------------- the network


def test_a_partition_loses_datagrams_and_holds_the_streams_across_the_cut(tmp_path):
    plan = [{"kind": "partition", "groups": [["attacker"]], "at": 2.0, "duration": 2.0}]
    _, events, findings = play(tmp_path, plan, transport="udp")
    across = [
        e
        for e in events
        if e["event"] == "received"
        and ((e["sender"] == "attacker") != (e["receiver"] == "attacker"))
        and "/truth/" not in e["key"]
        and "/control" not in e["key"]
    ]
    assert across and not [e for e in across if 2.0 + 1e-9 < e["t"] < 4.0 - 1e-9]
    cut = [e for e in events if e["event"] == "impaired" and e["reasons"] == ["partition"]]
    assert {e["action"] for e in cut} == {"dropped", "held"}
    assert all(e["action"] == "held" for e in cut if "/state" in e["key"])
    released = [e for e in across if "/state" in e["key"] and e["t"] == pytest.approx(4.0, abs=0.2)]
    assert released  # the held states arrive when it heals: the cut was shorter than the lease
    held(findings)


def test_a_degraded_link_follows_the_other_profile_for_its_duration(tmp_path):
    plan = [{"kind": "degrade", "target": "attacker", "profile": "3g-degraded", "at": 2.0, "duration": 4.0}]
    _, events, findings = play(tmp_path, plan)
    delays = [
        (e["t"], e["delay"])
        for e in events
        if e["event"] == "impaired" and e["action"] == "delivered" and "attacker" in (e["sender"], e["receiver"])
    ]
    inside = [d for t, d in delays if 2.0 <= t < 6.0]
    outside = [d for t, d in delays if t < 2.0 or t >= 8.0]
    assert min(inside) >= 0.25 and max(outside) < 0.1  # 3g-degraded's base delay against wifi's few ms
    held(findings)


# ---------------------------------------------------------------- clocks and sensors


def test_a_clock_jump_stamps_the_peers_messages_with_its_own_time(tmp_path):
    _, events, findings = play(
        tmp_path, [{"kind": "clock", "target": "attacker", "at": 2.0, "offset": 3.0, "duration": 3.0}]
    )
    skew = [e["message"]["t"] - e["t"] for e in sent(events, "fix", "attacker")]
    times = [e["t"] for e in sent(events, "fix", "attacker")]
    assert all(abs(s - (3.0 if 2.0 <= t < 5.0 else 0.0)) < 1e-9 for s, t in zip(skew, times, strict=True))
    held(findings)


@pytest.mark.parametrize("mode", ["jump", "freeze", "spoof"])
def test_a_lying_gps_reports_what_the_fault_says(tmp_path, mode):
    fault = {"kind": "gps", "target": "defender", "mode": mode, "at": 2.0, "duration": 4.0}
    fault |= {"offset": [30.0, 0.0]} if mode == "jump" else {"position": [5.0, 5.0]} if mode == "spoof" else {}
    _, events, findings = play(tmp_path, [fault])
    scenario = game()
    truth = {
        round(e["t"], 3): scenario.map.to_local(e["message"]["lat"], e["message"]["lon"])
        for e in sent(events, "truth", "defender")
    }
    fixes = [
        (e["t"], np.array(scenario.map.to_local(e["message"]["lat"], e["message"]["lon"])))
        for e in sent(events, "fix", "defender")
    ]
    lying = [(t, p) for t, p in fixes if 2.0 <= t < 6.0]
    assert len(lying) >= 3
    for t, p in lying:
        error = p - np.array(truth[round(t, 3)])
        if mode == "jump":
            assert np.hypot(*(error - [30.0, 0.0])) < 8.0  # the offset, give or take the GPS's own error
        elif mode == "spoof":
            assert p == pytest.approx([5.0, 5.0], abs=1e-6)
    if mode == "freeze":
        assert all(np.allclose(p, lying[0][1], atol=1e-6) for _, p in lying)
    honest = [p - np.array(truth[round(t, 3)]) for t, p in fixes if t >= 6.0]
    assert honest and max(np.hypot(*e) for e in honest) < 8.0
    held(findings)


def test_a_fault_counts_from_the_event_it_names(tmp_path):
    plan = [{"kind": "pause", "target": "defender", "after": "attacker.goes", "at": 0.5, "duration": 1.0}]
    outcome, events, _ = play(tmp_path, plan, seed=0)  # the attacker of seed 0 goes after 3.3 s
    (happened,) = [e for e in events if e["event"] == "happened" and e["name"] == "attacker.goes"]
    (fault,) = outcome.faults
    assert (
        fault["t"] == pytest.approx(happened["t"] + 0.5, abs=1e-9)
        and 0.0 <= happened["t"] - outcome.notes["attacker.committed_at"] <= 0.1 + 1e-9
    )


# ---------------------------------------------------------------- the checker and run directories


def test_the_checker_catches_a_torn_log_a_lost_message_and_a_verdict_the_truth_denies(tmp_path):
    outcome, _, findings = play(tmp_path, [])
    held(findings)
    run = tmp_path / "run"
    lines = (run / "events.jsonl").read_text().splitlines()
    # A state message its receiver never got, with nothing to excuse it.
    k = next(j for j, line in enumerate(lines) if '"received"' in line and "/state" in line and '"seq":3' in line)
    (run / "events.jsonl").write_text("\n".join(lines[:k] + lines[k + 1 :]) + "\n")
    assert {f.name: f.held for f in check_run(run)}["reliable"] is False
    (run / "events.jsonl").write_text("\n".join(lines) + '\n{"event":"sent","t":')
    assert "events.jsonl is torn at line" in {f.name: f for f in check_run(run)}["logs"].evidence
    (run / "events.jsonl").write_text("\n".join(lines) + "\n")
    verdict = {f.name: f for f in check_run(run)}["verdict"]
    assert verdict.held is True
    text = (run / "events.jsonl").read_text()
    forged = "attacker returned the flag" if "captured" in outcome.reason else "attacker captured"
    (run / "events.jsonl").write_text(text.replace(json.dumps(outcome.reason), json.dumps(forged)))
    assert {f.name: f.held for f in check_run(run)}["verdict"] is False


def test_the_checker_names_a_link_a_kernel_run_left_in_the_host_and_not_a_later_one_of_its_name(tmp_path):
    play(tmp_path, [])
    run = tmp_path / "run"
    (run / "peers").mkdir()  # as a live run's directory, which started no process
    processes.begin(run)
    lo = int(Path("/sys/class/net/lo/ifindex").read_text())

    def network(**added):
        (run / "endpoint.json").write_text(json.dumps({"network": added}))
        return {f.name: f for f in check_run(run)}["leftovers"]

    leftovers = network(link="lo", ifindex=lo, route=None)
    assert leftovers.held is False and leftovers.evidence == "left behind: link lo"
    # A link of the run's name, but not the run's: the next kernel run takes the name of the last.
    assert network(link="lo", ifindex=lo + 1000, route=None).held is True
    assert network(link="bcat-none", ifindex=lo, route="198.19.255.0/24").held is True


def test_the_checker_takes_no_failsafe_from_before_the_uav_lost_its_ground_station(bearcat_simulate):
    """A failsafe the UAV applied before its ground station was gone (on a
    slow start, in an earlier gap) is no answer to the loss that came after."""
    run = bearcat_simulate(
        "search", [{"kind": "kill", "target": "gs", "at": 6.0}], scenario__time_limit=12.0, rules__grid=35
    )
    assert run.held("failsafe") is True
    log = run.directory / "events.jsonl"
    events = [json.loads(line) for line in log.read_text().splitlines()]
    for e in events:
        if e["event"] == "did" and "failsafe" in e["what"]:
            e["t"] = e["at"] = 2.0
    log.write_text("".join(json.dumps(e) + "\n" for e in events))
    failsafe = {f.name: f for f in check_run(run.directory)}["failsafe"]
    assert failsafe.held is False and failsafe.evidence == "UAV q1 lost its ground station at 6.0 s and did nothing"


def test_a_second_run_into_the_same_directory_gets_its_own(tmp_path):
    path = tmp_path / "game.toml"
    path.write_text(scenario_text(time_limit=3.0))
    out = tmp_path / "out"
    assert main(["simulate", str(path), "--out", str(out)]) == 0
    first = (out / "seed-3" / "events.jsonl").read_bytes()
    assert main(["simulate", str(path), "--out", str(out), "--seed", "4"]) == 0
    assert (out / "seed-3" / "events.jsonl").read_bytes() == first and not (out / "seed-4").exists()
    assert (tmp_path / "out-1" / "seed-4" / "events.jsonl").exists()
    assert fresh(out) == tmp_path / "out-2" and fresh(tmp_path / "new") == tmp_path / "new"
    assert main(["check", str(out / "seed-3")]) == 0
