"""The resumable batch runner on real processes and a real Dask scheduler:
results land as they finish, a killed worker loses nothing already written,
and the same call again finishes the rest without redoing a trial."""

import json
import os
import signal

import pytest

from bearcat.studies.batch import BatchInterrupted, read_results, run_batch


def square(task: dict) -> dict:
    """Records that it ran (a file per key) and, for the task marked to die,
    kills its own worker process the first time it is run."""
    marks = task["marks"]
    runs = os.path.join(marks, f"ran-{task['key']}")
    with open(runs, "a") as f:
        f.write("x")
    if task.get("die") and not os.path.exists(os.path.join(marks, "survive")):
        os.kill(os.getpid(), signal.SIGKILL)
    return {"key": task["key"], "value": task["n"] ** 2}


def tasks(marks, n=12, die=None):
    return [{"key": f"t{i}", "n": i, "marks": str(marks), "die": i == die} for i in range(n)]


def runs_of(marks, key):
    path = marks / f"ran-{key}"
    return len(path.read_text()) if path.exists() else 0


def test_every_result_lands_once_and_a_second_call_runs_nothing(tmp_path):
    out = tmp_path / "results.jsonl"
    seen = []
    results = run_batch(tasks(tmp_path), square, out, workers=2, on_result=seen.append)
    assert {k: r["value"] for k, r in results.items()} == {f"t{i}": i * i for i in range(12)}
    assert len(out.read_text().splitlines()) == 12 and len(seen) == 12
    again = run_batch(tasks(tmp_path), square, out, workers=2)
    assert again == results
    assert all(runs_of(tmp_path, f"t{i}") == 1 for i in range(12))


def test_a_killed_worker_keeps_finished_trials_and_the_rerun_does_only_the_rest(tmp_path):
    out = tmp_path / "results.jsonl"
    with pytest.raises(BatchInterrupted, match="run the same command again"):
        run_batch(tasks(tmp_path, n=40, die=20), square, out, workers=2)
    kept = read_results(out)
    assert "t20" not in kept and all(r["value"] == int(k[1:]) ** 2 for k, r in kept.items())
    (tmp_path / "survive").touch()
    results = run_batch(tasks(tmp_path, n=40, die=20), square, out, workers=2)
    assert sorted(results) == sorted(f"t{i}" for i in range(40))
    lines = [json.loads(line)["key"] for line in out.read_text().splitlines()]
    assert len(lines) == len(set(lines)) == 40
    # Trials finished before the crash were not run again.
    assert all(runs_of(tmp_path, k) == 1 for k in kept)


def test_a_line_cut_short_by_a_crash_is_redone(tmp_path):
    out = tmp_path / "results.jsonl"
    out.write_text('{"key": "t0", "value": 0}\n{"key": "t1", "val')
    results = run_batch(tasks(tmp_path, n=3), square, out, workers=1)
    assert sorted(results) == ["t0", "t1", "t2"] and results["t1"]["value"] == 1
    assert runs_of(tmp_path, "t0") == 0 and runs_of(tmp_path, "t1") == 1
    # The new results start on lines of their own: a fresh read finds them all.
    assert sorted(read_results(out)) == ["t0", "t1", "t2"]


def test_duplicate_keys_are_refused(tmp_path):
    with pytest.raises(ValueError, match="unique"):
        run_batch(tasks(tmp_path, n=2) * 2, square, tmp_path / "r.jsonl")


def test_a_dask_scheduler_runs_the_same_batch(tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cluster:
        results = run_batch(tasks(tmp_path), square, tmp_path / "r.jsonl", scheduler=cluster.scheduler_address)
    assert {k: r["value"] for k, r in results.items()} == {f"t{i}": i * i for i in range(12)}


def test_an_unreachable_scheduler_is_one_clear_error(tmp_path):
    pytest.importorskip("distributed")
    with pytest.raises(BatchInterrupted, match=r"no Dask scheduler answered at tcp://127\.0\.0\.1:9 within"):
        run_batch(tasks(tmp_path, n=1), square, tmp_path / "r.jsonl", scheduler="tcp://127.0.0.1:9")
