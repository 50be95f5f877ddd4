"""``bearcat study fake-out|go-no-go|search``: the field studies of thesis
3.5 and 6.2.4 as batches of simulated games, resumable, with a table at the
end (``DIR/results.jsonl`` per game, ``DIR/summary.json``)."""

from __future__ import annotations

import json
from pathlib import Path

from bearcat import arguments
from bearcat.output import Output
from bearcat.progress import counting
from bearcat.scenarios.schema import TRANSPORTS
from bearcat.scenarios.studies import STUDIES
from bearcat.writing import make_directory, writing


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "study",
        description="fake-out: the aided attacker's fake-out against an unaided and an aided defender (3.5.1). "
        "go-no-go: how often an attacker's go, decided on what the network delivered, is false, per network "
        "profile (3.5.2). search: reachability-guided UAV search against a lawnmower sweep and the nearest "
        "unobserved point: time until the defender is found, and the attacker's wins (6.2.4).",
    )
    p.add_argument("study", choices=tuple(STUDIES))
    p.add_argument("--trials", type=int, default=50, metavar="N", help="games per scenario and profile (default 50)")
    p.add_argument("--seed", type=arguments.seed, default=0, metavar="S", help="seed of the first game (default 0)")
    p.add_argument("--netem", nargs="+", metavar="PROFILE", help="profiles to compare (go-no-go; default all four)")
    p.add_argument(
        "--transport",
        nargs="+",
        choices=TRANSPORTS,
        help="transports to compare (default: each scenario's own): tcp, udp or both",
    )
    p.add_argument("--workers", type=int, metavar="N", help="worker processes (default: one per core)")
    p.add_argument("--out", type=Path, metavar="DIR", help="results directory (default ./studies/STUDY)")
    p.add_argument(
        "--json",
        action="store_true",
        help="print the table's rows (DIR/summary.json) as JSON and nothing else on stdout (the table goes to stderr)",
    )
    p.set_defaults(run=run)


def run(args) -> int:
    from bearcat.netem.profiles import load_profile
    from bearcat.scenarios.batch import run_batch
    from bearcat.scenarios.schema import load_scenario
    from bearcat.scenarios.studies import play_task, study_tasks, summarise, summarise_search
    from bearcat.solve_ahead import solve_ahead

    for profile in args.netem or ():
        load_profile(profile)
    if args.trials < 1:
        raise arguments.UsageError("--trials must be at least 1")
    arguments.check_seeds(args.seed, args.trials)
    report = Output(args.json)
    out = args.out or Path("studies") / args.study
    make_directory(out, "results directory")
    # Solve each scenario's game once here, so the workers only load it.
    for name in STUDIES[args.study]["scenarios"]:
        scenario = load_scenario(name)
        solve_ahead(scenario, scenario.netem)
    tasks = study_tasks(args.study, args.trials, args.seed, args.netem, args.transport)
    with writing(out, "results directory"):
        with counting(len(tasks), args.study, "game") as finished:
            results = run_batch(tasks, play_task, out / "results.jsonl", workers=args.workers, on_result=finished)
        rows = (summarise_search if args.study == "search" else summarise)(results.values())
        (out / "summary.json").write_text(json.dumps(rows, indent=2) + "\n")
    report.say(_search_table(rows) if args.study == "search" else _goes_table(rows))
    report.say(f"per-game results in {out}/results.jsonl; replay one with bearcat simulate SCENARIO --seed S --netem P")
    report.json(rows)
    return 0


def _search_table(rows) -> str:
    lines = [
        f"{'search':<14}{'games':>6}{'found':>7}{'median s':>10}{'mean s':>8}{'attacker wins':>15}{'95% interval':>15}"
    ]
    for r in rows:
        median = "-" if r["median_time_to_find"] is None else f"{r['median_time_to_find']:.1f}"
        mean = "-" if r["mean_time_to_find"] is None else f"{r['mean_time_to_find']:.1f}"
        low, high = r["win_rate_95"]
        lines.append(
            f"{r['search']:<14}{r['games']:>6}{r['found']:>7}{median:>10}{mean:>8}"
            f"{r['attacker_wins']:>9} ({100 * r['attacker_win_rate']:.0f}%){f'{100 * low:.0f}-{100 * high:.0f}%':>13}"
        )
    return "\n".join(lines)


def _goes_table(rows) -> str:
    lines = [
        f"{'scenario':<26}{'network':<17}{'games':>6}{'attacker wins':>15}{'95% interval':>14}{'goes':>6}"
        f"{'false goes':>12}{'really open':>13}{'of them won':>13}"
    ]
    for r in rows:
        rate = "" if r["false_go_rate"] is None else f" ({100 * r['false_go_rate']:.0f}%)"
        low, high = r["attacker_win_interval"]
        network = f"{r['netem'] or 'its own'}/{r['transport']}"
        lines.append(
            f"{r['scenario']:<26}{network:<17}{r['games']:>6}"
            f"{r['attacker_wins']:>9} ({100 * r['attacker_win_rate']:.0f}%){100 * low:>7.0f}-{100 * high:.0f}%"
            f"{r['goes']:>6}{r['false_goes']:>6}{rate:<6}{r['goes_really_open']:>13}{r['really_open_won']:>13}"
        )
    return "\n".join(lines)
