"""A fault plan reaches a peer the launcher did not start.

A person's walker (``--joins defender``) holds the only process of the
defender, so the launcher cannot signal it: it announces the fault, and
the peer pauses itself past the lease (but back within the lease the
referee grants a gone player), then kills itself with a real SIGKILL.
The referee sees it go both times, the game ends naming the fault, and
``bearcat check`` holds every invariant.
"""

import json
import subprocess
import sys

from bearcat.agents.ground_station.event_log import read_events
from bearcat.scenarios.faults import parse_faults, write_faults
from tests.support.live_runs import printed_command, start_launcher
from tests.support.scenario_files import write_scenario

LEASE = 3.0
PAUSE = {"kind": "pause", "target": "defender", "at": 1.0, "duration": 1.5 * LEASE}
KILL = {"kind": "kill", "target": "defender", "at": 1.0 + 1.5 * LEASE + 2.0}


def test_a_peer_started_by_hand_pauses_and_kills_itself_on_the_launchers_notice(tmp_path):
    path = write_scenario(tmp_path, time_limit=60.0, netem="ideal", lease=LEASE)
    plan = tmp_path / "plan.toml"
    write_faults(plan, parse_faults([PAUSE, KILL]))
    out = tmp_path / "run"
    launcher = start_launcher(path, out, "--joins", "defender", "--faults", str(plan))
    person = None
    try:
        command = printed_command(launcher, "bearcat peer walker")
        assert command[command.index("--faults") + 1] == str((out / "faults.toml").resolve())
        person = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
        said, _ = person.communicate(timeout=120)
        output, _ = launcher.communicate(timeout=120)
    finally:
        for p in (launcher, person):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
    assert person.returncode == -9 and f"peer defender: killed by fault[1] (kill defender at {KILL['at']:g} s" in said
    assert launcher.returncode == 0, output
    events = read_events(out / "events.jsonl")
    start = next(e["t"] for e in events if e["event"] == "fault" and e["fault"] == 0) - PAUSE["at"]
    seen = [
        (e["event"], e["t"] - start)
        for e in events
        if e["event"] in ("gone", "alive") and e["key"].endswith("/defender")
    ]
    # Gone at the lease, as a frozen process's session would be, back as the pause ends, gone at once when killed.
    assert [what for what, _ in seen][-3:] == ["gone", "alive", "gone"], seen
    gone, back, killed = (t for _, t in seen[-3:])
    assert PAUSE["at"] + LEASE <= gone < PAUSE["at"] + PAUSE["duration"]
    assert PAUSE["at"] + PAUSE["duration"] <= back < KILL["at"]
    assert KILL["at"] <= killed < KILL["at"] + LEASE
    assert "walker defender is gone" in json.loads((out / "outcome.json").read_text())["reason"]
    applied = [e for e in read_events(out / "peers" / "defender.jsonl") if e["event"] == "fault-applied"]
    assert [(e["fault"], e["kind"]) for e in applied] == [(0, "pause"), (1, "kill")]
    checked = subprocess.run([sys.executable, "-m", "bearcat", "check", str(out)], capture_output=True, text=True)
    assert checked.returncode == 0, checked.stdout
    assert "pause defender seen gone" in checked.stdout and "kill defender seen gone" in checked.stdout
    assert "walker defender is gone: ended by fault[1] (kill defender" in checked.stdout
