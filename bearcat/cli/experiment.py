"""``bearcat experiment pursuit``: the comparison trials of thesis 5.3.2 as a
resumable batch, written to a run directory:

- ``trials.jsonl``: one line per trial, appended as trials finish;
- ``setup.json``: the setup the trials were run with (a rerun into the same
  directory must match it, so resumed results stay comparable);
- ``table.json`` and ``table.md``: Table 5.1 beside the thesis's values, with
  capture-time quartiles;
- ``histograms.png``: capture-time differences as in Fig. 5.11.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

from bearcat.cli import arguments
from bearcat.cli.arguments import Commands
from bearcat.cli.output import Output
from bearcat.cli.progress import counting
from bearcat.cli.writing import writing
from bearcat.maps import list_maps
from bearcat.studies.batch import run_batch
from bearcat.studies.pursuit_experiment import PursuitSetup, run_trial, summarise, trial_tasks

DEFAULT_DOMAINS = ("square-10", "triangle-10", "maze-10")


def register(commands: Commands) -> None:
    experiment = commands.add_parser("experiment")
    kinds = experiment.add_subparsers(dest="experiment", metavar="EXPERIMENT", required=True)
    p = kinds.add_parser(
        "pursuit",
        help="safe-reachable-area pursuit against pure pursuit (thesis Table 5.1, Fig. 5.11)",
        description="Runs both pursuit strategies from the same random initial conditions against the "
        "farthest-point evader and tabulates how often area pursuit captures sooner. Resumes an interrupted "
        "run in the same --out directory without redoing finished trials.",
    )
    p.add_argument(
        "--domain",
        nargs="+",
        default=list(DEFAULT_DOMAINS),
        metavar="MAP",
        help="maps to play on (default: square-10 triangle-10 maze-10)",
    )
    p.add_argument(
        "--pursuers", nargs="+", type=int, default=[1, 2, 3], metavar="N", help="pursuer counts (default 1 2 3)"
    )
    p.add_argument(
        "--trials", type=int, default=500, metavar="K", help="trials per domain and pursuer count (default 500)"
    )
    p.add_argument("--seed", type=arguments.seed, default=0, help="seed of the whole run (default 0)")
    arguments.add_batch_options(p, "trials")
    p.add_argument(
        "--out",
        type=Path,
        default=Path("pursuit-experiment"),
        metavar="DIR",
        help="run directory (default ./pursuit-experiment)",
    )
    p.add_argument(
        "--dt", type=arguments.positive, default=PursuitSetup.dt, help=f"time step (default {PursuitSetup.dt})"
    )
    p.add_argument(
        "--max-time",
        type=arguments.positive,
        default=PursuitSetup.max_time,
        help=f"longest chase in time units (default {PursuitSetup.max_time:g})",
    )
    p.add_argument(
        "--gradient",
        choices=("boundary", "finite"),
        default=PursuitSetup.gradient,
        help="area gradient in non-convex domains (default boundary)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print the table (DIR/table.json) as JSON and nothing else on stdout (the text goes to stderr)",
    )
    p.set_defaults(run=run_pursuit)


def run_pursuit(args) -> int:
    unknown = [d for d in args.domain if d not in list_maps()]
    if unknown:
        raise arguments.UsageError(f"unknown domain {unknown[0]!r}; built-in maps are {', '.join(list_maps())}")
    if args.trials < 1 or any(n < 1 for n in args.pursuers):
        raise arguments.UsageError("--trials and every --pursuers count must be at least 1")
    report = Output(args.json)
    setup = PursuitSetup(dt=args.dt, max_time=args.max_time, gradient=args.gradient)
    tasks = trial_tasks(args.domain, args.pursuers, args.trials, args.seed, setup)
    with writing(args.out, "run directory"):
        _check_setup(args.out, {"seed": args.seed, **asdict(setup)})
        with counting(len(tasks), "trials", "trial") as finished:
            results = run_batch(
                tasks,
                run_trial,
                args.out / "trials.jsonl",
                workers=args.workers,
                scheduler=args.cluster,
                on_result=finished,
            )
        wanted = {t["key"] for t in tasks}
        table = summarise([r for k, r in results.items() if k in wanted], args.domain, args.pursuers)
        (args.out / "table.json").write_text(json.dumps(table, indent=2) + "\n")
        markdown = table_markdown(table, args.domain, args.pursuers)
        (args.out / "table.md").write_text(markdown + "\n")
        from bearcat.figures.games import pursuit_histograms

        pursuit_histograms(table, args.domain, args.pursuers).savefig(args.out / "histograms.png", dpi=110)
    report.say(markdown)
    report.say(f"wrote {args.out / 'trials.jsonl'}, table.md, table.json and histograms.png in {args.out}")
    report.json(table)
    return 0


def _check_setup(out: Path, setup: dict) -> None:
    """Refuse to mix trials of another setup into a run directory."""
    path = out / "setup.json"
    if path.exists():
        recorded = json.loads(path.read_text())
        if recorded != setup:
            changed = ", ".join(f"{k} {recorded.get(k)!r} -> {v!r}" for k, v in setup.items() if recorded.get(k) != v)
            raise arguments.UsageError(f"{out} holds trials of another setup ({changed}); choose another --out")
        return
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(setup, indent=2) + "\n")


def table_markdown(table: dict, domains, counts) -> str:
    """Table 5.1 with ours beside the thesis's, then capture-time medians."""

    def share(row) -> str:
        thesis = "" if row["thesis_percent"] is None else f" ({row['thesis_percent']:.1f})"
        return f"{row['area_faster_percent']:.1f}{thesis}, n={row['trials']}"

    def times(row) -> str:
        a, p = row["area_time_quartiles"], row["pure_time_quartiles"]
        return f"{_q(a)} / {_q(p)} ({row['area_uncaptured']}/{row['pure_uncaptured']})"

    return "\n".join(
        [
            "% of trials where area pursuit captured sooner than pure pursuit: ours (thesis)",
            "",
            *_grid(table, domains, counts, share),
            "",
            "median capture time [quartiles], area / pure (uncaptured within the limit)",
            "",
            *_grid(table, domains, counts, times),
        ]
    )


def _grid(table: dict, domains, counts, cell) -> list[str]:
    """A Markdown table: a row per domain, a column per pursuer count."""
    lines = [
        "| domain | " + " | ".join(f"{n} pursuer{'s' if n > 1 else ''}" for n in counts) + " |",
        "|---" * (len(counts) + 1) + "|",
    ]
    for domain in domains:
        rows = [table.get(f"{domain}/{n}") for n in counts]
        lines.append(f"| {domain} | " + " | ".join("-" if row is None else cell(row) for row in rows) + " |")
    return lines


def _q(quartiles) -> str:
    if quartiles[1] is None:
        return "-"
    return f"{quartiles[1]:.1f} [{quartiles[0]:.1f}, {quartiles[2]:.1f}]"
