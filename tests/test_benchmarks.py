"""The benchmarks as programs: one told to stop (SIGTERM, as a batch
system or ``timeout`` tells it) stops at once and leaves no process behind."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.support.live_runs import wait_for

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"


def children(pid: int) -> set[int]:
    """The processes whose parent is ``pid``."""
    found = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            found |= {int(c) for c in (task / "children").read_text().split()}
        except OSError:
            continue
    return found


def group(pgid: int) -> set[int]:
    """The processes, zombies aside, of process group ``pgid``."""
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[0] != "Z" and int(fields[2]) == pgid:  # state, ppid, pgrp
            found.add(int(stat.parent.name))
    return found


def test_sigterm_stops_the_field_benchmark_at_once_with_its_phones():
    """Mid-measurement, with its phones publishing and its ground station
    answering them, ``benchmarks/field.py`` told SIGTERM ends within seconds
    (not after the minute of fixes it was asked for), says so, prints no
    result for the run it dropped, and leaves none of its phones running."""
    bench = subprocess.Popen(
        [sys.executable, str(BENCHMARKS / "field.py"), "--latency-only", "--phones", "2", "--duration", "60"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
        start_new_session=True,  # its own process group, to find (and at worst kill) its phones by
    )
    try:
        assert wait_for(lambda: len(children(bench.pid)) >= 2 or bench.poll() is not None, 60)
        assert bench.poll() is None, bench.communicate()[0]
        time.sleep(3.0)  # the phones up and publishing, the ground station answering
        bench.send_signal(signal.SIGTERM)
        asked = time.monotonic()
        try:
            output, _ = bench.communicate(timeout=15)
        except subprocess.TimeoutExpired:
            raise AssertionError("the benchmark was still running 15 s after SIGTERM") from None
        assert time.monotonic() - asked < 10, output
        assert bench.returncode != 0 and "stopped" in output and "phones (peers" not in output, output
        assert group(bench.pid) == set()
    finally:
        try:
            os.killpg(bench.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        bench.wait()
