"""``bearcat simulate``: play a scenario in one process, in virtual time.

One trial per seed (``--seed`` for the first, then the next ones), each
deterministic: the same seed gives the same game and the same event log. A
line per trial and a tally go to stdout (``--json``: one JSON object per
trial, then the tally); ``--out DIR`` keeps each trial's run directory
``DIR/seed-S/``: ``events.jsonl``, ``outcome.json``, ``map.geojson`` and
the Rerun ``recording.rrd``.
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from dataclasses import asdict
from pathlib import Path

from bearcat.agents.ground_station.rerun_recording import finish_run
from bearcat.progress import solve_bars
from bearcat.scenarios.schema import list_scenarios, load_scenario
from bearcat.scenarios.simulate import simulate


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="play a scenario in virtual time, every peer in this process",
        description="Play a scenario with every peer in one process, in virtual time, through the same "
        f"codec and network emulation as a live run. Built-in scenarios: {', '.join(list_scenarios())}.",
    )
    p.add_argument("scenario", metavar="SCENARIO", help="a built-in scenario name or a scenario TOML file")
    p.add_argument("--trials", type=int, default=1, metavar="N", help="games to play, seeds S, S+1, ... (default 1)")
    p.add_argument("--seed", type=int, metavar="S", help="seed of the first trial (default: the scenario's)")
    p.add_argument("--netem", metavar="PROFILE", help="network profile to use instead of the scenario's")
    p.add_argument("--out", type=Path, metavar="DIR", help="keep each trial's event log and outcome here")
    p.add_argument("--json", action="store_true", help="print one JSON object per trial, then the tally")
    p.set_defaults(run=run)


def run(args) -> int:
    scenario = load_scenario(args.scenario)
    if args.trials < 1:
        print("bearcat: error: --trials must be at least 1", file=sys.stderr)
        return 2
    first = scenario.seed if args.seed is None else args.seed
    tally: Counter = Counter()
    solving = solve_bars()

    for seed in range(first, first + args.trials):
        events = None if args.out is None else args.out / f"seed-{seed}" / "events.jsonl"
        outcome = simulate(scenario, seed=seed, netem=args.netem, events=events, ctf_progress=solving)
        solving.close()
        record = asdict(outcome)
        if events is not None:
            (events.parent / "outcome.json").write_text(json.dumps(record, indent=2) + "\n")
            finish_run(events.parent, scenario)
        tally[outcome.winner or "none"] += 1
        if args.json:
            print(json.dumps(record), flush=True)
        else:
            who = f"{outcome.winner} wins" if outcome.winner else "no winner"
            print(f"seed {seed}: {who} at {outcome.elapsed:.1f} s: {outcome.reason}", flush=True)
    summary = {
        "scenario": scenario.name,
        "netem": args.netem or scenario.netem,
        "trials": args.trials,
        "wins": dict(sorted(tally.items())),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        wins = ", ".join(f"{team} {n}" for team, n in sorted(tally.items()))
        print(f"{scenario.name} under {summary['netem']}: {args.trials} trial(s); wins: {wins}")
        if args.out is not None:
            print(f"event logs and recordings in {args.out}/seed-*/ (bearcat view {args.out}/seed-{first})")
    return 0
