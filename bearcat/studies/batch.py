"""Run many independent trials, resumably, on a local process pool or a Dask
cluster.

Each task is a JSON-ready dict with a unique ``"key"``; each result is a
JSON-ready dict that carries the same key and is appended to a JSON-lines
file the moment it arrives. A run that is interrupted (Ctrl-C, a killed
worker, a lost cluster) keeps every line already written, and the same call
again skips the keys it finds there, so finished trials are never redone.
Tasks carry their own seeds, so a trial's result does not depend on which
worker ran it or in what order.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Callable, Iterable
from concurrent.futures import CancelledError, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

log = logging.getLogger(__name__)

__all__ = ["BatchInterrupted", "read_results", "run_batch"]

SAME_EVERYWHERE = ("bearcat", "numpy", "numba")
"""The packages a trial's numbers depend on, which every machine of a Dask
cluster must have in this machine's versions for its results to be a local
run's (the solvers' cache keys hash them for the same reason)."""

CONNECT_TIMEOUT = 10
"""Seconds to wait for a Dask scheduler to answer."""


class BatchInterrupted(RuntimeError):
    """The batch stopped early; the results so far are on disk."""


def read_results(path: Path) -> dict[str, dict]:
    """The results already in ``path`` by key. A last line cut short by a
    crash is ignored (and will be redone), as is any line that is not a
    result object."""
    results: dict[str, dict] = {}
    if not path.exists():
        return results
    with path.open(encoding="utf-8") as f:
        for number, line in enumerate(f, start=1):
            try:
                result = json.loads(line)
                results[result["key"]] = result
            except (json.JSONDecodeError, KeyError, TypeError):
                log.warning("%s line %d is not a complete result; its trial will be run again", path, number)
    return results


def run_batch(
    tasks: Iterable[dict],
    work: Callable[[dict], dict],
    out: Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    on_result: Callable[[dict], None] | None = None,
    preflight: Callable[[list[dict]], str | None] | None = None,
) -> dict[str, dict]:
    """Run ``work(task)`` for every task whose key is not yet in ``out`` and
    return all results by key, old and new. ``workers`` bounds the local
    process pool (default: the CPU count); ``scheduler`` (``tcp://host:port``)
    sends the tasks to a Dask cluster instead, whose scheduler and workers
    must be able to import ``work`` (the scheduler reads the tasks too) and
    run this machine's versions of ``SAME_EVERYWHERE``. ``on_result`` is
    called once per finished task, old ones included, for a progress display.
    ``preflight(tasks)`` says why a machine cannot play the tasks (None if
    it can); every Dask worker is asked before the first task is sent, and
    one that cannot is refused by name."""
    tasks = list(tasks)
    keys = [t["key"] for t in tasks]
    if len(set(keys)) != len(keys):
        raise ValueError("task keys must be unique")
    out.parent.mkdir(parents=True, exist_ok=True)
    results = read_results(out)
    for key in keys:
        if key in results and on_result is not None:
            on_result(results[key])
    todo = [t for t in tasks if t["key"] not in results]
    if not todo:
        return results
    _end_last_line(out)
    with out.open("a", encoding="utf-8") as sink:

        def record(result: dict) -> None:
            sink.write(json.dumps(result, separators=(",", ":")) + "\n")
            sink.flush()
            os.fsync(sink.fileno())
            results[result["key"]] = result
            if on_result is not None:
                on_result(result)

        if scheduler is None:
            _run_local(todo, work, workers, record, out)
        else:
            _run_dask(todo, work, scheduler, record, out, preflight)
    return results


def _end_last_line(path: Path) -> None:
    """Close a last line cut short by a crash, so new results start on a line of their own."""
    if path.exists() and path.stat().st_size > 0:
        with path.open("rb+") as f:
            f.seek(-1, os.SEEK_END)
            if f.read(1) != b"\n":
                f.write(b"\n")


def _run_local(todo, work, workers, record, out) -> None:
    with ProcessPoolExecutor(max_workers=workers or os.cpu_count()) as pool:
        futures = [pool.submit(work, task) for task in todo]
        try:
            for future in as_completed(futures):
                record(future.result())
        except BrokenProcessPool:
            for future in futures:
                future.cancel()
            raise BatchInterrupted(
                f"a worker process died; the finished trials are kept in {out}, run the same command again to resume"
            ) from None
        except BaseException:
            for future in futures:
                future.cancel()
            raise


def _run_dask(todo, work, scheduler, record, out, preflight) -> None:
    distributed = _distributed()
    with _connect(distributed.Client, scheduler) as client:
        _check_versions(client, scheduler)
        if preflight is not None:
            for worker, why in sorted(client.run(preflight, todo).items()):
                if why is not None:
                    raise BatchInterrupted(f"the Dask worker at {worker} cannot play these games: {why}")
        futures = client.map(work, todo, pure=False)
        try:
            for future in distributed.as_completed(futures):
                record(future.result())
        except (OSError, TimeoutError, CancelledError, distributed.KilledWorker) as exc:
            why = " ".join(str(exc).split())  # Dask's messages run over several lines
            raise BatchInterrupted(
                f"the Dask cluster at {scheduler} failed ({why}); the finished trials are kept in {out}, "
                "run the same command again to resume"
            ) from None
        finally:
            client.cancel(futures)


def _distributed():
    """Dask's ``distributed``, an optional dependency (the ``cluster`` extra)."""
    try:
        import distributed
    except ImportError:
        raise BatchInterrupted(
            "a Dask scheduler was given but the 'distributed' package is not installed; pip install 'bearcat[cluster]'"
        ) from None
    return distributed


def _connect(client, scheduler: str):
    """A Dask client of the scheduler at ``scheduler``, or one sentence saying why not."""
    try:
        return client(scheduler, timeout=f"{CONNECT_TIMEOUT}s")
    except ValueError as exc:
        raise BatchInterrupted(
            f"{scheduler!r} is not a Dask scheduler's address ({exc}); it reads tcp://HOST:PORT"
        ) from None
    except (OSError, TimeoutError):
        raise BatchInterrupted(
            f"no Dask scheduler answered at {scheduler} within {CONNECT_TIMEOUT} s; "
            "is 'dask scheduler' running there, with its port open to this machine?"
        ) from None


def _check_versions(client, scheduler: str) -> None:
    """Refuse a cluster whose scheduler or workers run other versions of
    ``SAME_EVERYWHERE`` than this machine: their trials could differ from
    a local run's, and a scheduler without bearcat cannot even read the
    tasks. Workers that join later are not asked."""
    versions = client.get_versions(packages=list(SAME_EVERYWHERE))
    mine = _wanted(versions["client"])
    machines = {f"scheduler at {scheduler}": versions["scheduler"]}
    machines |= {f"worker at {worker}": found for worker, found in versions["workers"].items()}
    for machine, found in machines.items():
        theirs = _wanted(found)
        differ = [name for name in SAME_EVERYWHERE if theirs[name] != mine[name]]
        if differ:
            raise BatchInterrupted(
                f"the Dask {machine} has {_listed(theirs, differ)} where this machine has {_listed(mine, differ)}; "
                "install the same versions on every machine"
            )


def _wanted(versions: dict) -> dict[str, str | None]:
    return {name: versions["packages"].get(name) for name in SAME_EVERYWHERE}


def _listed(versions: dict[str, str | None], names: list[str]) -> str:
    return ", ".join(f"{name} {versions[name] or '(not installed)'}" for name in names)
