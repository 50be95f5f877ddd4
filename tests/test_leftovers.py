"""The checker's ``leftovers``: a process is the run's when the run recorded
starting it, by its number and its start time, and not because its command
line names the run directory.

One short live game is played; the checker, run under ``timeout`` or from a
script (each naming the run directory on its command line), finds nothing
of it left. A process recorded as the launcher records its peers is named
while it runs; a recorded number that now belongs to a process started at
another time is not the run's; a run directory that recorded no processes,
or whose processes ran under another boot, is said to be beyond judging.
"""

import shutil
import signal
import subprocess
import sys

import msgspec
import pytest

from bearcat.runtime import processes
from bearcat.suites.checker import check_run
from tests.support.live_runs import start_launcher
from tests.support.scenario_files import write_scenario

pytestmark = pytest.mark.xdist_group("leftovers")  # one game for the module, in one xdist worker

CHECK = (sys.executable, "-m", "bearcat", "check")
NOTHING_LEFT = ("held", "no process of the run is left")


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    """The run directory of one short live game that ended cleanly."""
    base = tmp_path_factory.mktemp("played")
    launcher = start_launcher(write_scenario(base, time_limit=6.0), base / "run")
    output, _ = launcher.communicate(timeout=180)
    assert launcher.returncode == 0, output
    return (base / "run").resolve()


@pytest.fixture
def run(played, tmp_path):
    """A copy of the played run's directory, for a test to add to."""
    copy = tmp_path / "run"
    shutil.copytree(played, copy)
    return copy.resolve()


@pytest.fixture
def sleeper():
    """A process of the test's own, ended with it."""
    process = subprocess.Popen(["sleep", "600"])
    yield process
    process.kill()
    process.wait()


def leftovers(run):
    return next(f for f in check_run(run) if f.name == "leftovers")


def said_of_leftovers(printed):
    """The mark and evidence ``bearcat check`` printed on its leftovers line."""
    mark, _, evidence = next(line.split(None, 2) for line in printed.splitlines() if line.split()[1:2] == ["leftovers"])
    return mark, evidence


def test_the_launcher_records_every_peer_it_started(played):
    started = processes.recorded(played)
    assert sorted(p.name for p in started) == ["attacker", "defender", "gs"]
    assert all(p.host == processes.host() and not processes.running(p) for p in started)


def test_a_checker_under_timeout_or_in_a_script_finds_nothing_of_a_clean_run_left(played, tmp_path):
    wrapped = subprocess.run(["timeout", "60", *CHECK, str(played)], capture_output=True, text=True)
    assert wrapped.returncode == 0 and said_of_leftovers(wrapped.stdout) == NOTHING_LEFT, wrapped.stdout
    script = tmp_path / "check.sh"
    script.write_text(f'#!/bin/sh\n"{sys.executable}" -m bearcat check "$1"\necho "checked $1"\n')
    scripted = subprocess.run(["sh", str(script), str(played)], capture_output=True, text=True)
    assert scripted.returncode == 0 and said_of_leftovers(scripted.stdout) == NOTHING_LEFT, scripted.stdout


def test_a_recorded_process_still_running_is_left_behind_by_name(run, sleeper):
    processes.record(run, "attacker", sleeper.pid)
    finding = leftovers(run)
    assert finding.held is False and finding.evidence == f"left behind: attacker (pid {sleeper.pid})"
    said = subprocess.run([*CHECK, str(run)], capture_output=True, text=True)
    assert said.returncode == 1 and said_of_leftovers(said.stdout) == (
        "BROKEN",
        f"left behind: attacker (pid {sleeper.pid})",
    )
    sleeper.send_signal(signal.SIGKILL)
    sleeper.wait()
    assert leftovers(run).held is True


def test_a_recorded_number_a_later_process_took_is_not_the_runs(run, sleeper):
    """The record says process N started at one time; the process numbered N
    now started at another: the kernel gave the number to someone else."""
    processes.record(run, "attacker", sleeper.pid)
    assert leftovers(run).held is False
    path = run / processes.PROCESSES
    *kept, last = path.read_bytes().splitlines()
    earlier = msgspec.structs.replace(msgspec.json.decode(last, type=processes.Started), start=0)
    path.write_bytes(b"".join(line + b"\n" for line in [*kept, msgspec.json.encode(earlier)]))
    assert processes.running(earlier) is False
    assert leftovers(run).held is True


def test_a_run_that_recorded_no_processes_or_ran_elsewhere_cannot_be_judged(run):
    path = run / processes.PROCESSES
    started = processes.recorded(run)
    path.unlink()
    finding = leftovers(run)
    assert finding.held is None and finding.evidence.startswith("cannot tell: this run recorded no processes")
    elsewhere = [msgspec.structs.replace(p, host=f"another {p.host}") for p in started]
    path.write_bytes(b"".join(msgspec.json.encode(p) + b"\n" for p in elsewhere))
    finding = leftovers(run)
    assert finding.held is None and "another boot or PID namespace" in finding.evidence
    path.write_bytes(b'{"name": "attacker", "pid": ')
    finding = leftovers(run)
    assert finding.held is None and finding.evidence == "cannot tell: processes.jsonl line 1 does not read as a process"
