"""``bearcat simulate``: play a scenario in one process, in virtual time.

One trial per seed (``--seed`` for the first, then the next ones), each
deterministic: the same seed gives the same game and the same event log. A
line per trial and a tally go to stdout (``--json``: one JSON object per
trial, then the tally, with the lines on stderr); ``--out DIR`` keeps each trial's run directory
``DIR/seed-S/``: ``events.jsonl``, ``outcome.json``, ``scenario.toml``,
``map.geojson`` and the Rerun ``recording.rrd`` (a ``DIR`` that holds
something already is left alone: the runs go to ``DIR-1``, ...).
``--faults FILE`` applies a fault plan, in virtual time.
"""

from __future__ import annotations

import json
from collections import Counter
from contextlib import nullcontext
from dataclasses import asdict
from pathlib import Path

from bearcat.agents.ground_station.rerun_recording import finish_run
from bearcat.cli import arguments
from bearcat.cli.arguments import Commands
from bearcat.cli.output import Output
from bearcat.cli.presolve import presolve
from bearcat.cli.writing import make_directory, writing
from bearcat.runtime.run_directory import fresh, write_scenario
from bearcat.runtime.simulate import simulate
from bearcat.scenarios.faults import load_faults
from bearcat.scenarios.schema import TRANSPORTS, list_scenarios, load_scenario


def register(commands: Commands) -> None:
    p = commands.add_parser(
        "simulate",
        description="Play a scenario with every peer in one process, in virtual time, through the same "
        f"codec and network emulation as a live run. Built-in scenarios: {', '.join(list_scenarios())}.",
    )
    p.add_argument("scenario", metavar="SCENARIO", help="a built-in scenario name or a scenario TOML file")
    p.add_argument("--trials", type=int, default=1, metavar="N", help="games to play, seeds S, S+1, ... (default 1)")
    p.add_argument("--seed", type=arguments.seed, metavar="S", help="seed of the first trial (default: the scenario's)")
    p.add_argument("--netem", metavar="PROFILE", help="network profile to use instead of the scenario's")
    p.add_argument(
        "--transport",
        choices=TRANSPORTS,
        help="how fixes and guidance travel: tcp (retransmitted, late) or udp (lost); default: the scenario's",
    )
    p.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="keep each trial's event log and outcome here (DIR-1, DIR-2, ... if DIR holds something already)",
    )
    p.add_argument(
        "--faults",
        type=Path,
        metavar="FILE",
        help="a fault plan ([[fault]] tables) to apply instead of the scenario's own",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object per trial, then the tally, and nothing else on stdout (the text goes to stderr)",
    )
    p.set_defaults(run=run)


def run(args) -> int:
    scenario = load_scenario(args.scenario)
    if args.trials < 1:
        raise arguments.UsageError("--trials must be at least 1")
    first = scenario.seed if args.seed is None else args.seed
    arguments.check_seeds(first, args.trials)
    out = Output(args.json)
    plan = None if args.faults is None else load_faults(args.faults, scenario)
    if args.out is not None:
        args.out = fresh(args.out)
        make_directory(args.out, "run directory")
    presolve(scenario, args.netem or scenario.netem)
    tally: Counter = Counter()

    for seed in range(first, first + args.trials):
        events = None if args.out is None else args.out / f"seed-{seed}" / "events.jsonl"
        with nullcontext() if args.out is None else writing(args.out, "run directory"):
            if events is not None:
                events.parent.mkdir()
                write_scenario(events.parent, scenario)
            outcome = simulate(
                scenario, seed=seed, netem=args.netem, transport=args.transport, events=events, faults=plan
            )
            record = asdict(outcome)
            if events is not None:
                (events.parent / "outcome.json").write_text(json.dumps(record, indent=2) + "\n")
                finish_run(events.parent, scenario)
        tally[outcome.winner or "none"] += 1
        who = f"{outcome.winner} wins" if outcome.winner else "no winner"
        out.say(f"seed {seed}: {who} at {outcome.elapsed:.1f} s: {outcome.reason}")
        out.json(record, indent=None)
    summary = {
        "scenario": scenario.name,
        "netem": args.netem or scenario.netem,
        "transport": args.transport or scenario.transport,
        "trials": args.trials,
        "wins": dict(sorted(tally.items())),
    }
    wins = ", ".join(f"{team} {n}" for team, n in sorted(tally.items()))
    out.say(f"{scenario.name} under {summary['netem']}: {args.trials} trial(s); wins: {wins}")
    if args.out is not None:
        out.say(f"event logs and recordings in {args.out}/seed-*/ (bearcat view {args.out}/seed-{first})")
    out.json(summary, indent=None)
    return 0
