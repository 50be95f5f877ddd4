"""The first game: how long ``bearcat run SCENARIO`` takes from the command
to the game's start when nothing is cached, on provisional sets (the
default) and with ``--wait-for-sets``, in the same run.

    python benchmarks/first_game.py                 # fake-out, numba's cache as it is
    python benchmarks/first_game.py --cold          # numba's cache empty too, as in a fresh clone
    python benchmarks/first_game.py --scenario small-area --repeat 5 --provisional-only

Each launch gets an empty set cache (and, with ``--cold``, an empty numba
cache) and is stopped with Ctrl-C a few seconds after it says the game
started, so the solve behind the game is not timed. Three marks, in seconds
from the command: the launcher up (its router listening: imports, and with
``--wait-for-sets`` the whole solve), the ground station up (the ``warmed``
line of its event log: its imports, its sets loaded and its query code
readied, while the other peers start) and the game's start; and how long
the ground station took to answer the game's first pair of fixes with a
full guidance (heading and region) once the game was on, in
milliseconds. The machine is shared
and noisy: read the medians of several repeats.
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
PLAYED = 3.0  # s of the game played before the launch is stopped, for its first guidance


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
            if "game started" in seen:
                time.sleep(PLAYED)
            launcher.send_signal(signal.SIGINT)
            launcher.communicate(timeout=120)
        finally:
            if launcher.poll() is None:
                launcher.kill()
        if "game started" not in seen:
            raise RuntimeError(f"{' '.join(command)} ended without starting its game")
        events = list(read_events(f"{scratch}/run/peers/gs.jsonl"))
        warmed = [e["t"] for e in events if e["event"] == "warmed"]
        if not warmed:
            raise RuntimeError("the ground station's event log has no 'warmed' line")
        seen["gs up"] = warmed[0] - epoch
        sent = [e for e in events if e["event"] == "sent"]
        begun = min(e["t"] for e in sent if e["key"].endswith("/state") and e["message"]["phase"] == "running")
        # The ground station's log says when it sent each guidance; the launcher's holds its body.
        bodies = {
            (e["key"], e["message"].get("seq")): e["message"]
            for e in read_events(f"{scratch}/run/events.jsonl")
            if e["event"] == "sent" and "/guidance/" in e["key"]
        }
        answers = [
            (e["t"], m)
            for e in sent
            if "/guidance/" in e["key"] and e["t"] > begun
            if (m := bodies.get((e["key"], e["seq"]))) is not None and m["value"] is not None
        ]
        seen["first answer ms"] = (answers[0][0] - answers[0][1]["t"]) * 1e3 if answers else float("nan")
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
    print(f"{'sets':>17} | launcher up | ground station up | game started (range) | first full answer, ms")
    medians = {}
    for wait in (False,) if args.provisional_only else (False, True):
        runs = [first_game(args.scenario, args.cold, wait) for _ in range(args.repeat)]
        median = medians[wait] = {mark: statistics.median(run[mark] for run in runs) for mark in runs[0]}
        begun = [run["game started"] for run in runs]
        kind = "full grid first" if wait else "provisional"
        print(
            f"{kind:>17} | {median['launcher up']:11.1f} | {median['gs up']:17.1f} | "
            f"{median['game started']:.1f} ({min(begun):.1f}-{max(begun):.1f}){'':>9} | "
            f"{median['first answer ms']:.1f}",
            flush=True,
        )
    if args.provisional_only:
        return
    ratio = medians[True]["game started"] / medians[False]["game started"]
    print(f"the game starts {ratio:.1f}x sooner on provisional sets ({args.repeat} launch(es) each, medians)")


if __name__ == "__main__":
    main()
