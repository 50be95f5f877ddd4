"""Fault-injection suites as a user runs them: the built-in suite in both
runtimes, a suite of one's own from the fault-injection page's example,
and the pytest plugin's fixtures."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from bearcat.cli.main import main
from bearcat.scenarios.faults import KINDS, FaultError
from bearcat.suites.suite import builtin_suite, load_suite
from tests.support.system import missing_kernel_network


def test_the_builtin_suite_covers_every_fault_kind_against_the_three_games():
    _, cases = load_suite(builtin_suite())
    kinds = {f.kind for case in cases for f in case.faults}
    assert kinds == set(KINDS)
    assert {case.scenario.name for case in cases} == {"fake-out", "go-no-go", "search"}


def test_the_builtin_suite_holds_in_virtual_time(tmp_path, capsys):
    assert main(["faults", "builtin", "--out", str(tmp_path / "sim")]) == 0
    said = capsys.readouterr().out
    report = json.loads((tmp_path / "sim" / "report.json").read_text())
    assert report["passed"] and len(report["cases"]) == 9
    assert {s["case"] for s in report["skipped"]} == {"fake-out-starved-and-full"}
    assert "9 of 9 runs held every invariant they expect" in said
    for case in report["cases"]:
        assert (tmp_path / "sim" / case["case"] / "seed-0" / "events.jsonl").exists()


LIVE_ONLY_HERE = (
    "fake-out-stop-ground-station",
    "fake-out-pause-*",
    "fake-out-restarts",
    "fake-out-starved-and-full",
    "go-no-go-partition-when-the-attacker-goes",
)
"""The built-in cases whose mechanism no other live test exercises: a
stopped and a paused process (SIGSTOP), a clock and a GPS lie, restarts,
a cgroup's CPU and a full tmpfs, a partition at the go. A kill is
``test_live``'s, an outage on a kernel network the test below, a UAV cut
off from its ground station ``test_uav``'s; in virtual time all ten run."""


def test_the_builtin_suite_holds_live(tmp_path):
    """Every peer its own process, the faults real signals, cgroups and a tmpfs."""
    cases = [word for case in LIVE_ONLY_HERE for word in ("--case", case)]
    done = subprocess.run(
        [
            *(sys.executable, "-m", "bearcat", "faults", "builtin", "--runtime", "live", *cases),
            *("--jobs", "2", "--out", str(tmp_path / "live")),
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    report = json.loads((tmp_path / "live" / "report.json").read_text())
    assert report["passed"] and len(report["cases"]) == 6 and not report["skipped"]
    assert "6 of 6 runs held every invariant they expect" in done.stdout


@pytest.mark.xdist_group("kernel")
@pytest.mark.skipif(missing_kernel_network() is not None, reason=str(missing_kernel_network()))
def test_a_partition_on_a_kernel_network_is_noticed_at_the_lease_and_healed(tmp_path):
    done = subprocess.run(
        [
            *(sys.executable, "-m", "bearcat", "faults", "builtin", "--runtime", "live", "--network", "kernel"),
            *("--case", "go-no-go-outage-of-the-defender", "--out", str(tmp_path / "kernel")),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    (case,) = json.loads((tmp_path / "kernel" / "report.json").read_text())["cases"]
    seen = float(case["detected"].split()[0])
    # Real packets, really dropped: the link's 3 s lease runs out, and the router sweeps. The lease
    # runs from the last packet that got through, which may precede the cut by up to Zenoh's
    # keep-alive interval (a quarter of the lease) when a fix was lost or late at the cut.
    assert 3.0 * 3 / 4 <= seen <= 3.0 + 2.0
    # The report gives the delay to 0.01 s and the evidence to 0.1 s, each rounded from the same time.
    said = re.search(r"outage defender seen gone after (\d+\.\d) s \(lease 3 s\)", case["evidence"]["detection"])
    assert said is not None and abs(float(said.group(1)) - seen) <= 0.05 + 0.005, case["evidence"]["detection"]
    assert case["evidence"]["leftovers"] == "no process, link or route of the run is left"
    added = json.loads(next((tmp_path / "kernel").glob("*/seed-0/endpoint.json")).read_text())["network"]
    assert added["link"].startswith("bcat") and added["route"].startswith("198.1")


FAULTS_PAGE = (Path(__file__).resolve().parent.parent / "docs" / "faults.md").read_text()
SUITE = re.search(r"\*\*Suites\.\*\*.*?```toml\n(.*?)```", FAULTS_PAGE, flags=re.S).group(1)
"""The example suite of the fault-injection page, as a user would copy it."""


def test_a_suite_of_ones_own_runs_with_one_command_and_fails_when_an_expectation_does(tmp_path, capsys):
    suite = tmp_path / "mine.toml"
    suite.write_text(SUITE)
    assert main(["faults", str(suite), "--out", str(tmp_path / "runs")]) == 0
    said = capsys.readouterr().out
    assert "defender-killed  0" in said and "defender-killed  1" in said and "2/2 held" in said
    suite.write_text(SUITE.replace('expect = ["verdict", "detection"]', 'expect = ["verdict", "failsafe"]'))
    assert main(["faults", str(suite), "--out", str(tmp_path / "runs")]) == 1  # no UAV: nothing to fail safe
    assert "did not apply: failsafe" in capsys.readouterr().out
    assert (tmp_path / "runs-1" / "report.json").exists()  # the first run's directory is left alone


@pytest.mark.parametrize(
    ("change", "said"),
    [
        (('expect = ["verdict", "detection"]', 'expect = ["verdikt"]'), "expect: 'verdikt' is not an invariant"),
        (('scenario = "fake-out"', 'scenario = "fake-in"'), "case[0] (defender-killed): there is no scenario"),
        (('target = "defender"', 'target = "nobody"'), "fault[0].target: there is no peer 'nobody'"),
    ],
)
def test_a_bad_suite_is_one_sentence_naming_the_case(tmp_path, change, said):
    suite = tmp_path / "mine.toml"
    suite.write_text(SUITE.replace(*change))
    with pytest.raises(
        FaultError, match=said.replace("[", r"\[").replace("]", r"\]").replace("(", r"\(").replace(")", r"\)")
    ):
        load_suite(suite)


def test_the_pytest_plugin_is_registered_and_its_fixtures_judge_a_run(pytestconfig, bearcat_simulate, bearcat_check):
    assert pytestconfig.pluginmanager.hasplugin("bearcat")
    run = bearcat_simulate(
        "fake-out",
        [{"kind": "restart", "target": "attacker", "at": 3.0}],
        scenario__time_limit=12.0,
        rules__grid=21,
    )
    run.assert_held()
    assert run.held("leftovers") is None and run.outcome["faults"][0]["kind"] == "restart"
    assert bearcat_check(run.directory).findings.keys() == run.findings.keys()
