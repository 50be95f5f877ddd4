"""Starting a live run as a user does (``bearcat run`` in a process of its own) and watching it."""

import os
import subprocess
import sys
import time

import pytest

from bearcat.agents.ground_station.event_log import read_events


def start_launcher(scenario, out, *flags: str) -> subprocess.Popen:
    """``bearcat run SCENARIO --out OUT FLAGS...``, its output on a pipe (text)."""
    return subprocess.Popen(
        [sys.executable, "-m", "bearcat", "run", str(scenario), "--out", str(out), *flags],
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def game_started(out) -> bool:
    """Whether the launcher of the run in ``out`` has recorded the game running."""
    events = out / "events.jsonl"
    return events.exists() and any(e.get("message", {}).get("phase") == "running" for e in read_events(events))


def wait_for(predicate, timeout) -> bool:
    """Whether ``predicate()`` came true within ``timeout`` seconds (asked every tenth of one)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.1)
    return predicate()


def printed_command(launcher, marker: str) -> list[str]:
    """The command the launcher printed for a peer to start by hand: the first of its lines holding ``marker``."""
    for line in launcher.stdout:
        if marker in line:
            return line.split()
    pytest.fail(f"the launcher ended without printing a command with {marker!r}")
