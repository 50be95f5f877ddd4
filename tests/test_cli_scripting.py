"""The command line as scripts use it: ``--json`` output that pipes, a fast
``--help``, and one sentence (never a traceback) for a bad seed or a place
that refuses a write. Real processes, real files, a real full filesystem."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from bearcat.cli.main import COMMANDS, build_parser, main
from bearcat.cli.writing import WriteError, writing
from tests.support.scenario_files import write_scenario

GAME = ("--map", "ctf-10", "--grid", "17", "--scheme", "first", "--capture-radius", "1.0", "--stages", "return")
STATE = ("--attacker", "5,8", "--defender", "5,1")
HEAVY = {"numpy", "numba", "zenoh", "rerun", "scipy", "matplotlib"}


def bearcat(*words: str, cwd=None, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "bearcat", *words],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=cwd,
        env={**os.environ, **env},
    )


def one_sentence(run: subprocess.CompletedProcess) -> str:
    """The last line of stderr of a run refused with exit code 2, and no traceback."""
    assert run.returncode == 2, run.stdout + run.stderr
    assert "Traceback" not in run.stderr, run.stderr
    return run.stderr.strip().splitlines()[-1]


@pytest.fixture
def scenario(tmp_path):
    return str(write_scenario(tmp_path))


@pytest.fixture
def regular_file(tmp_path):
    """A file standing where a command is told to make a directory."""
    path = tmp_path / "a-file"
    path.write_text("not a directory\n")
    return path


@pytest.fixture
def full_disk(tmp_path):
    """A 64 KiB tmpfs: too small for an event log or a solved set."""
    mountpoint = tmp_path / "full"
    mountpoint.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mountpoint)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        yield mountpoint
    finally:
        subprocess.run(["umount", str(mountpoint)], check=True)


# --- --json alone: JSON on stdout and nothing else ---


@pytest.mark.parametrize(
    "words, person",
    [
        (("solve", "ctf", *GAME, "--json"), "R_A: attacker wins from"),
        (("query", "ctf", *GAME, *STATE, "--plot", "FIGURE", "--json"), "wrote FIGURE"),
        (("play", "ctf", *GAME, *STATE, "--plot", "FIGURE", "--json"), "wrote FIGURE"),
        (
            ("solve", "openloop", "--map", "ctf-10", "--attacker", "2,2", "--target", "8,8,1", "--spacing", "0.5")
            + ("--plot", "FIGURE", "--json"),
            "wrote FIGURE",
        ),
        (("maps", "show", "ctf-10", "-o", "FIGURE", "--json"), "wrote FIGURE"),
    ],
    ids=["solve-ctf", "query-ctf", "play-ctf", "solve-openloop", "maps-show"],
)
def test_json_without_a_file_is_all_that_stdout_holds(words, person, tmp_path):
    figure = str(tmp_path / "figure.png")
    run = bearcat(*(w.replace("FIGURE", figure) for w in words))
    assert run.returncode == 0, run.stderr
    json.loads(run.stdout)
    # The lines for a person are not lost: they went to stderr.
    assert person.replace("FIGURE", figure) in run.stderr


def test_json_with_a_file_leaves_stdout_to_the_person(tmp_path):
    out = tmp_path / "answer.json"
    run = bearcat("query", "ctf", *GAME, *STATE, "--json", str(out))
    assert run.returncode == 0, run.stderr
    assert json.loads(out.read_text())["winner"] == "attacker"
    assert "attacker wins" in run.stdout and f"wrote {out}" in run.stdout


def test_simulate_json_is_one_object_per_trial_then_the_tally(scenario, tmp_path):
    run = bearcat("simulate", scenario, "--trials", "2", "--json", "--out", str(tmp_path / "out"))
    assert run.returncode == 0, run.stderr
    *trials, tally = [json.loads(line) for line in run.stdout.splitlines()]
    assert [t["seed"] for t in trials] == [3, 4] and tally["trials"] == 2
    assert "seed 3:" in run.stderr and "event logs and recordings in" in run.stderr


def test_experiment_json_is_the_table(tmp_path):
    out = tmp_path / "run"
    words = ("--domain", "square-10", "--pursuers", "1", "--trials", "2", "--workers", "1", "--out", str(out))
    run = bearcat("experiment", "pursuit", *words, "--json")
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout) == json.loads((out / "table.json").read_text())
    assert "| square-10 |" in run.stderr


@pytest.mark.slow
def test_study_json_is_the_summary(tmp_path):
    """Slow: the holding study plays on field-50's 45-point game, which
    takes a minute or more to solve the first time."""
    out = tmp_path / "study"
    words = ("study", "holding", "--trials", "1", "--netem", "ideal", "--rate", "1", "5", "--workers", "1")
    run = bearcat(*words, "--guidance", "plain", "calibrated", "--out", str(out), "--json")
    assert run.returncode == 0, run.stderr
    rows = json.loads(run.stdout)
    assert rows == json.loads((out / "summary.json").read_text())
    assert {(r["guidance"], r["rate"]) for r in rows} == {(g, rate) for g in ("plain", "calibrated") for rate in (1, 5)}
    assert all(r["games"] == 1 and r["netem"] == "ideal" for r in rows)
    assert (out / "holding.png").stat().st_size > 10_000


# --- a --help that needs no solver ---


@pytest.mark.parametrize("option", ["--version", "--help"])
def test_version_and_help_import_no_numerics_network_or_plotting(option):
    run = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "bearcat", option], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0, run.stderr
    imported = {line.split("|")[-1].strip().split(".")[0] for line in run.stderr.splitlines() if "|" in line}
    assert "bearcat" in imported and not imported & HEAVY


def test_every_command_is_registered_by_the_module_the_table_names():
    for name, (modules, _) in COMMANDS.items():
        registered = next(a for a in build_parser(name)._actions if a.dest == "command").choices
        # The command, and only commands the table gives one of the same modules.
        assert name in registered and all(set(COMMANDS[other][0]) & set(modules) for other in registered)


@pytest.mark.parametrize(
    "words",
    [(name,) for name in COMMANDS]
    + [("solve", "openloop"), ("solve", "ctf"), ("query", "ctf"), ("play", "ctf"), ("experiment", "pursuit")]
    + [("solve", "maneuver"), ("play", "maneuver")]
    + [("maps", "list"), ("maps", "show")],
)
def test_every_command_answers_help(words, capsys):
    with pytest.raises(SystemExit) as exit:
        main([*words, "--help"])
    assert exit.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: bearcat {' '.join(words)}")


# --- seeds ---


@pytest.mark.parametrize("seed", ["-1", "4294967296"])
@pytest.mark.parametrize(
    "words",
    [
        ("simulate", "SCENARIO"),
        ("run", "SCENARIO"),
        ("peer", "walker", "--scenario", "SCENARIO"),
        ("study", "fake-out"),
        ("experiment", "pursuit"),
        ("vehicle", "--home", "0,0,0"),
    ],
    ids=lambda words: words[0],
)
def test_a_seed_out_of_range_is_refused_before_anything_runs(words, seed, scenario, tmp_path):
    run = bearcat(*(scenario if w == "SCENARIO" else w for w in words), "--seed", seed, cwd=tmp_path)
    message = one_sentence(run)
    assert "--seed" in message and repr(seed) in message
    # No run or results directory: nothing was started.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["game.toml"]


def test_trials_that_run_past_the_largest_seed_are_refused(scenario):
    message = one_sentence(bearcat("simulate", scenario, "--seed", "4294967295", "--trials", "2"))
    assert message == "bearcat: error: --seed 4294967295 with 2 trials runs past the largest seed, 4294967295"


# --- places that refuse a write ---


@pytest.mark.parametrize(
    "words, what",
    [
        (("simulate", "SCENARIO", "--out", "DIR"), "run directory"),
        (("run", "SCENARIO", "--out", "DIR"), "run directory"),
        (("study", "fake-out", "--out", "DIR"), "results directory"),
        (("experiment", "pursuit", "--domain", "square-10", "--trials", "1", "--out", "DIR"), "run directory"),
        (("query", "ctf", *GAME, *STATE, "--json", "DIR/answer.json"), "JSON file"),
        (("play", "ctf", *GAME, *STATE, "--plot", "DIR/play.png"), "figure"),
        (("maps", "show", "ctf-10", "-o", "DIR/map.png"), "figure"),
    ],
    ids=["simulate", "run", "study", "experiment", "query-json", "play-plot", "maps-show"],
)
def test_a_file_where_a_directory_must_be_is_named(words, what, scenario, regular_file):
    place = regular_file / "out"
    words = [scenario if w == "SCENARIO" else w.replace("DIR", str(place)) for w in words]
    message = one_sentence(bearcat(*words))
    assert message.startswith(f"bearcat: error: cannot write {what} {place}")
    assert message.endswith(f"{regular_file} is a file, not a directory")


@pytest.mark.parametrize("command", ["solve", "simulate"])
def test_a_cache_directory_under_a_file_is_named(command, scenario, regular_file):
    words = ("solve", "ctf", *GAME) if command == "solve" else ("simulate", scenario)
    cache = regular_file / "cache"
    message = one_sentence(bearcat(*words, BEARCAT_CACHE_DIR=str(cache)))
    assert message == f"bearcat: error: cannot write cache directory {cache}: {regular_file} is a file, not a directory"


def test_a_full_run_directory_is_named(scenario, full_disk):
    out = full_disk / "out"
    message = one_sentence(bearcat("simulate", scenario, "--out", str(out)))
    assert message == f"bearcat: error: cannot write run directory {out}: No space left on device"


def test_a_full_cache_directory_is_named(full_disk):
    cache = full_disk / "cache"
    message = one_sentence(bearcat("solve", "ctf", *GAME, BEARCAT_CACHE_DIR=str(cache)))
    # numpy reports a short write of the set without the OS's words.
    assert message.startswith(f"bearcat: error: cannot write cache directory {cache}: a write stopped short (")
    assert message.endswith("is its disk full?")


def test_a_full_device_for_the_json_file_is_named():
    message = one_sentence(bearcat("query", "ctf", *GAME, *STATE, "--json", "/dev/full"))
    assert message == "bearcat: error: cannot write JSON file /dev/full: No space left on device"


def test_an_error_about_another_place_keeps_its_traceback(tmp_path):
    """A guard names its own place only: any other OSError is a bug to see."""
    elsewhere = tmp_path / "elsewhere" / "file"
    with pytest.raises(FileNotFoundError), writing(tmp_path / "out", "run directory"):
        elsewhere.read_text()
    with pytest.raises(ConnectionRefusedError), writing(tmp_path / "out", "run directory"):
        raise ConnectionRefusedError(111, "Connection refused")
    with pytest.raises(WriteError, match="cannot write run directory"), writing(tmp_path / "out", "run directory"):
        (tmp_path / "out" / "deeper" / "events.jsonl").write_text("")
