"""The first game: how long ``bearcat run SCENARIO`` takes from the command
to the game's start when nothing is cached, on provisional sets (the
default) and with ``--wait-for-sets``, in the same run.

    python benchmarks/first_game.py                 # fake-out, numba's cache as it is
    python benchmarks/first_game.py --cold          # numba's cache empty too, as in a fresh clone
    python benchmarks/first_game.py --scenario small-area --repeat 5 --provisional-only

Each launch gets an empty set cache (and, with ``--cold``, an empty numba
cache) and is stopped with Ctrl-C as soon as it says the game started, so
the solve behind the game is not timed. Three marks, in seconds from the
command: the launcher up (its router listening: imports, and with
``--wait-for-sets`` the whole solve), the ground station's sets ready (the
first ``sets`` line of its event log: its imports and the provisional solve,
while the other peers start; sets loaded from the cache are ready before
the launcher is up) and the game's start. The machine is shared and noisy:
read the medians of several repeats.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time

from bearcat.agents.ground_station.event_log import read_events

MARKS = {"launcher up": re.compile(r"^network: "), "game started": re.compile(r"game started")}


def first_game(scenario: str, cold: bool, wait: bool) -> dict[str, float]:
    """Seconds from the command to each mark of one launch from empty caches."""
    with tempfile.TemporaryDirectory(prefix="bearcat-first-game-") as scratch:
        env = dict(os.environ, BEARCAT_CACHE_DIR=f"{scratch}/sets", PYTHONUNBUFFERED="1")
        if cold:
            env["NUMBA_CACHE_DIR"] = f"{scratch}/numba"
        command = [sys.executable, "-m", "bearcat", "run", scenario, "--out", f"{scratch}/run"]
        started, epoch = time.monotonic(), time.time()
        launcher = subprocess.Popen(
            [*command, *(["--wait-for-sets"] if wait else [])],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            env=env,
        )
        seen: dict[str, float] = {}
        pending = b""
        try:
            while "game started" not in seen and (chunk := launcher.stdout.read1(4096)):
                *lines, pending = re.split(rb"[\r\n]", pending + chunk)
                now = time.monotonic() - started
                for line in lines:
                    text = line.decode(errors="replace")
                    for mark, pattern in MARKS.items():
                        if mark not in seen and pattern.search(text):
                            seen[mark] = now
            launcher.send_signal(signal.SIGINT)
            launcher.communicate(timeout=120)
        finally:
            if launcher.poll() is None:
                launcher.kill()
        if "game started" not in seen:
            raise RuntimeError(f"{' '.join(command)} ended without starting its game")
        notes = [e["t"] for e in read_events(f"{scratch}/run/peers/gs.jsonl") if e["event"] == "sets"]
        seen["sets ready"] = notes[0] - epoch if notes else seen["launcher up"]
        return seen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="fake-out")
    parser.add_argument("--cold", action="store_true", help="an empty numba cache too, as after a fresh clone")
    parser.add_argument("--repeat", type=int, default=1, metavar="N", help="launches of each kind (default 1)")
    parser.add_argument("--provisional-only", action="store_true", help="skip the launches that wait for the full grid")
    args = parser.parse_args()
    print(f"{args.scenario}: seconds from `bearcat run` to each mark, empty set cache", end="")
    print(", empty numba cache" if args.cold else ", numba's cache as it is", flush=True)
    print(f"{'sets':>17} | launcher up | ground station's sets ready | game started (range)")
    medians = {}
    for wait in (False,) if args.provisional_only else (False, True):
        runs = [first_game(args.scenario, args.cold, wait) for _ in range(args.repeat)]
        median = medians[wait] = {mark: statistics.median(run[mark] for run in runs) for mark in runs[0]}
        begun = [run["game started"] for run in runs]
        kind = "full grid first" if wait else "provisional"
        print(
            f"{kind:>17} | {median['launcher up']:11.1f} | {median['sets ready']:27.1f} | "
            f"{median['game started']:.1f} ({min(begun):.1f}-{max(begun):.1f})",
            flush=True,
        )
    if args.provisional_only:
        return
    ratio = medians[True]["game started"] / medians[False]["game started"]
    print(f"the game starts {ratio:.1f}x sooner on provisional sets ({args.repeat} launch(es) each, medians)")


if __name__ == "__main__":
    main()
