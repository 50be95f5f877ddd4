"""``bearcat study`` and ``bearcat experiment`` with ``--cluster`` on a real
Dask cluster: a ``dask scheduler`` and two ``dask worker`` processes on the
loopback, each worker one process of one thread, as a user starts them.

The cluster's games are the local run's, record for record; the client
solves nothing (the workers solve or load the sets in their own cache);
both workers play; a results file already holding some games is finished
without playing those again; and what can go wrong before the first game
(no scheduler there, no 'distributed', a scheduler without bearcat) is one
sentence and exit code 2.
"""

import json
import os
import signal
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

import pytest

from bearcat import __version__ as bearcat_version
from bearcat.netem.kernel.commands import die_with_parent

pytestmark = pytest.mark.xdist_group("cluster")  # one cluster for the module, in one xdist worker

# 2 cells x 3 seeds: 6 games, on the field-50 game other tests solve too.
STUDY = ("study", "holding", "--trials", "3", "--netem", "wifi", "--rate", "1", "--guidance", "plain", "worst-case")
EXPERIMENT = ("experiment", "pursuit", "--domain", "square-10", "--pursuers", "2", "--trials", "6", "--seed", "4")


def bearcat(*words, env=None, timeout=300):
    return subprocess.run(
        [sys.executable, "-m", "bearcat", *words],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=None if env is None else os.environ | env,
    )


def start(words, logs: Path, name: str, **options) -> subprocess.Popen:
    """A process of its own session (so stopping it stops its children),
    logging to ``logs/name.log``, that dies with the tests however they end
    (a worker's process dies with the nanny that started it)."""
    with (logs / f"{name}.log").open("w") as log:
        return subprocess.Popen(
            words,
            stdout=log,
            stderr=subprocess.STDOUT,
            cwd=logs,
            start_new_session=True,
            preexec_fn=die_with_parent,
            **options,
        )


def stop(process: subprocess.Popen) -> None:
    """SIGTERM to the process and its children, SIGKILL after 10 s."""
    for sent, wait in ((signal.SIGTERM, 10), (signal.SIGKILL, 5)):
        try:
            os.killpg(process.pid, sent)
        except ProcessLookupError:
            break
        try:
            process.wait(wait)
            break
        except subprocess.TimeoutExpired:
            continue


def scheduler_address(file: Path, process: subprocess.Popen) -> str:
    """The address the scheduler wrote to its ``--scheduler-file``, once it has."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and process.poll() is None:
        try:
            return json.loads(file.read_text())["address"]
        except (FileNotFoundError, json.JSONDecodeError, KeyError):
            time.sleep(0.2)
    raise RuntimeError(f"the scheduler wrote no address to {file}")


def scheduler(logs: Path, *python: str, env=None) -> tuple[subprocess.Popen, str]:
    """A ``dask scheduler`` on a free loopback port, and its address."""
    file = logs / "scheduler.json"
    words = [*python, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0"]
    process = start([*words, "--no-dashboard", "--scheduler-file", str(file)], logs, "scheduler", env=env)
    try:
        return process, scheduler_address(file, process)
    except BaseException:
        stop(process)
        raise


@pytest.fixture(scope="module")
def cluster(tmp_path_factory, private_cache_dir):
    """The scheduler's address and a Dask client of it, for the tests to ask
    the workers how many tasks each has run. The workers keep their sets in
    the session's cache, so a game another test solved is loaded."""
    distributed = pytest.importorskip("distributed")
    logs = tmp_path_factory.mktemp("cluster")
    processes = []
    try:
        process, address = scheduler(logs, sys.executable)
        processes.append(process)
        for name in ("one", "two"):
            words = [sys.executable, "-m", "distributed.cli.dask_worker", address, "--host", "127.0.0.1"]
            words += ["--nworkers", "1", "--nthreads", "1", "--no-dashboard", "--name", name]
            words += ["--local-directory", str(logs / name)]
            env = os.environ | {"BEARCAT_CACHE_DIR": str(private_cache_dir)}
            processes.append(start(words, logs, f"worker-{name}", env=env))
        with distributed.Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=120)
            yield address, client
    finally:
        for process in reversed(processes):
            stop(process)


def executed(client) -> dict[str, int]:
    """How many tasks each worker has run, by name."""
    counts = client.run(lambda dask_worker: (dask_worker.name, dask_worker.state.executed_count))
    return dict(counts.values())


def records(path: Path) -> dict[str, dict]:
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    by_key = {r["key"]: r for r in lines}
    assert len(by_key) == len(lines), "a key is in the results twice"
    return by_key


def difference(after: dict[str, int], before: dict[str, int]) -> dict[str, int]:
    return {name: count - before.get(name, 0) for name, count in after.items()}


@pytest.fixture(scope="module")
def cluster_study(cluster, tmp_path_factory):
    """The study played on the cluster by a client whose own cache is empty,
    and the tasks each worker ran for it."""
    address, client = cluster
    where = tmp_path_factory.mktemp("cluster-study")
    before = executed(client)
    run = bearcat(*STUDY, "--cluster", address, "--out", str(where / "out"), env={"BEARCAT_CACHE_DIR": str(where)})
    assert run.returncode == 0, run.stderr
    return where, difference(executed(client), before)


def test_the_cluster_plays_the_local_runs_games(cluster_study, tmp_path):
    where, _ = cluster_study
    local = bearcat(*STUDY, "--workers", "2", "--out", str(tmp_path))
    assert local.returncode == 0, local.stderr
    there, here = records(where / "out" / "results.jsonl"), records(tmp_path / "results.jsonl")
    assert len(here) == 6 and there == here
    summary = json.loads((where / "out" / "summary.json").read_text())
    assert summary == json.loads((tmp_path / "summary.json").read_text())


def test_the_workers_solve_or_load_the_sets_and_both_play(cluster_study, private_cache_dir):
    where, ran = cluster_study
    assert not list(where.glob("ctf/*.npy")), "the client solved sets its workers cannot read"
    assert list(private_cache_dir.glob("ctf/*.npy"))
    assert sorted(ran) == ["one", "two"] and all(n >= 1 for n in ran.values()) and sum(ran.values()) == 6


def test_a_resumed_cluster_run_plays_only_the_games_not_in_the_file(cluster, cluster_study, tmp_path):
    address, client = cluster
    where, _ = cluster_study
    done = (where / "out" / "results.jsonl").read_text().splitlines(keepends=True)
    (tmp_path / "results.jsonl").write_text("".join(done[:2]))
    before = executed(client)
    run = bearcat(*STUDY, "--cluster", address, "--out", str(tmp_path))
    assert run.returncode == 0, run.stderr
    assert sum(difference(executed(client), before).values()) == 4
    lines = (tmp_path / "results.jsonl").read_text().splitlines(keepends=True)
    assert lines[:2] == done[:2]
    assert records(tmp_path / "results.jsonl") == records(where / "out" / "results.jsonl")


def test_the_experiment_runs_the_same_trials_on_the_cluster(cluster, tmp_path):
    address, _ = cluster
    there = bearcat(*EXPERIMENT, "--cluster", address, "--out", str(tmp_path / "cluster"))
    here = bearcat(*EXPERIMENT, "--workers", "2", "--out", str(tmp_path / "local"))
    assert there.returncode == 0, there.stderr
    assert here.returncode == 0, here.stderr
    trials = records(tmp_path / "cluster" / "trials.jsonl")
    assert len(trials) == 6 and trials == records(tmp_path / "local" / "trials.jsonl")


def test_no_scheduler_at_the_address_is_one_sentence(tmp_path):
    pytest.importorskip("distributed")
    run = bearcat(*STUDY, "--cluster", "tcp://127.0.0.1:9", "--out", str(tmp_path))
    assert run.returncode == 2
    assert run.stderr.splitlines()[-1] == (
        "bearcat: error: no Dask scheduler answered at tcp://127.0.0.1:9 within 10 s; "
        "is 'dask scheduler' running there, with its port open to this machine?"
    )


def test_a_missing_distributed_names_the_extra_to_install(tmp_path):
    """As on a machine without the ``cluster`` extra: importing it fails."""
    code = (
        "import sys; sys.modules['distributed'] = None; from bearcat.cli.main import main; sys.exit(main(sys.argv[1:]))"
    )
    words = (*EXPERIMENT, "--cluster", "tcp://127.0.0.1:9", "--out", str(tmp_path))
    run = subprocess.run([sys.executable, "-c", code, *words], capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert run.stderr.splitlines()[-1] == (
        "bearcat: error: a Dask scheduler was given but the 'distributed' package is not installed; "
        "pip install 'bearcat[cluster]'"
    )


def test_a_scheduler_without_bearcat_is_refused_before_any_trial(tmp_path):
    """A scheduler started by a Python that has every installed package but
    bearcat: ``-S`` keeps the installed packages' folder (and the path file
    of bearcat's editable install) off its path, and the folder it gets
    instead holds links to all of them but bearcat's record."""
    pytest.importorskip("distributed")
    installed = Path(sysconfig.get_paths()["purelib"])
    site = tmp_path / "site"
    site.mkdir()
    for entry in installed.iterdir():
        if not entry.name.startswith(("bearcat", "__editable__.bearcat")):
            (site / entry.name).symlink_to(entry)
    process, address = scheduler(tmp_path, sys.executable, "-S", env=os.environ | {"PYTHONPATH": str(site)})
    try:
        run = bearcat(*EXPERIMENT, "--cluster", address, "--out", str(tmp_path / "out"))
    finally:
        stop(process)
    assert run.returncode == 2
    assert run.stderr.splitlines()[-1] == (
        f"bearcat: error: the Dask scheduler at {address} has bearcat (not installed) where this machine has "
        f"bearcat {bearcat_version}; install the same versions on every machine"
    )
    trials = tmp_path / "out" / "trials.jsonl"
    assert not trials.exists() or trials.read_text() == ""


def test_a_worker_that_cannot_import_a_plugin_is_refused_by_name_before_any_game(cluster, tmp_path):
    """The client imports a behaviour of its own from its PYTHONPATH; the
    workers, started without it, cannot: the study stops before any game,
    naming a worker and the module."""
    address, client = cluster
    (tmp_path / "only_here_tactics.py").write_text(
        "from bearcat.plugins import Behaviour\n\n\nclass Stand(Behaviour):\n"
        "    def decide(self, now, me, screen, situation):\n        return None\n"
    )
    varied = ("--vary", 'agent.attacker.behaviour="only_here_tactics:Stand"', "--vary", "agent.attacker.options={}")
    before = executed(client)
    run = bearcat(
        *STUDY, *varied, "--cluster", address, "--out", str(tmp_path / "out"), env={"PYTHONPATH": str(tmp_path)}
    )
    assert run.returncode == 2, run.stderr
    said = run.stderr.splitlines()[-1]
    assert said.startswith("bearcat: error: the Dask worker at tcp://127.0.0.1:"), said
    assert "cannot play these games: " in said and said.endswith(
        "agent[0].behaviour: 'only_here_tactics:Stand': module only_here_tactics cannot be imported: "
        "ModuleNotFoundError: No module named 'only_here_tactics'"
    ), said
    assert set(difference(executed(client), before).values()) == {0}
