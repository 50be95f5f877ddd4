"""``bearcat study fake-out|go-no-go|search``: the field studies of thesis
3.5 and 6.2.4 as batches of simulated games, resumable, with a table at the
end (``DIR/results.jsonl`` per game, ``DIR/summary.json``)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from bearcat.scenarios.studies import STUDIES


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "study",
        help="the fake-out, go/no-go and UAV search studies of thesis 3.5 and 6.2.4, as batches of simulated games",
        description="fake-out: the aided attacker's fake-out against an unaided and an aided defender (3.5.1). "
        "go-no-go: how often an attacker's go, decided on what the network delivered, is false, per network "
        "profile (3.5.2). search: reachability-guided UAV search against a lawnmower sweep and the nearest "
        "unobserved point: time until the defender is found, and the attacker's wins (6.2.4).",
    )
    p.add_argument("study", choices=tuple(STUDIES))
    p.add_argument("--trials", type=int, default=50, metavar="N", help="games per scenario and profile (default 50)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed of the first game (default 0)")
    p.add_argument("--netem", nargs="+", metavar="PROFILE", help="profiles to compare (go-no-go; default all four)")
    p.add_argument("--workers", type=int, metavar="N", help="worker processes (default: one per core)")
    p.add_argument("--out", type=Path, metavar="DIR", help="results directory (default ./studies/STUDY)")
    p.set_defaults(run=run)


def run(args) -> int:
    from tqdm import tqdm

    from bearcat.netem.profiles import load_profile
    from bearcat.scenarios.batch import run_batch
    from bearcat.scenarios.cast import build_cast
    from bearcat.scenarios.schema import load_scenario
    from bearcat.scenarios.studies import play_task, study_tasks, summarise, summarise_search

    for profile in args.netem or ():
        load_profile(profile)
    if args.trials < 1:
        print("bearcat: error: --trials must be at least 1", file=sys.stderr)
        return 2
    out = args.out or Path("studies") / args.study
    out.mkdir(parents=True, exist_ok=True)
    # Solve each scenario's game once here, so the workers only load it.
    for name in STUDIES[args.study]["scenarios"]:
        scenario = load_scenario(name)
        build_cast(scenario, load_profile(scenario.netem), 0, people=[], ground=True)
    tasks = study_tasks(args.study, args.trials, args.seed, args.netem)
    with tqdm(total=len(tasks), desc=args.study, unit="game", file=sys.stderr) as bar:
        results = run_batch(
            tasks, play_task, out / "results.jsonl", workers=args.workers, on_result=lambda r: bar.update(1)
        )
    if args.study == "search":
        rows = summarise_search(results.values())
        (out / "summary.json").write_text(json.dumps(rows, indent=2) + "\n")
        _print_search(rows)
    else:
        rows = summarise(results.values())
        (out / "summary.json").write_text(json.dumps(rows, indent=2) + "\n")
        _print_goes(rows)
    print(f"per-game results in {out}/results.jsonl; replay one with bearcat simulate SCENARIO --seed S --netem P")
    return 0


def _print_search(rows) -> None:
    print(
        f"{'search':<14}{'games':>6}{'found':>7}{'median s':>10}{'mean s':>8}{'attacker wins':>15}{'95% interval':>15}"
    )
    for r in rows:
        median = "-" if r["median_time_to_find"] is None else f"{r['median_time_to_find']:.1f}"
        mean = "-" if r["mean_time_to_find"] is None else f"{r['mean_time_to_find']:.1f}"
        low, high = r["win_rate_95"]
        print(
            f"{r['search']:<14}{r['games']:>6}{r['found']:>7}{median:>10}{mean:>8}"
            f"{r['attacker_wins']:>9} ({100 * r['attacker_win_rate']:.0f}%){f'{100 * low:.0f}-{100 * high:.0f}%':>13}"
        )


def _print_goes(rows) -> None:
    print(
        f"{'scenario':<26}{'network':<13}{'games':>6}{'attacker wins':>15}{'goes':>6}{'false goes':>12}"
        f"{'really open':>13}{'of them won':>13}"
    )
    for r in rows:
        rate = "" if r["false_go_rate"] is None else f" ({100 * r['false_go_rate']:.0f}%)"
        print(
            f"{r['scenario']:<26}{r['netem'] or 'its own':<13}{r['games']:>6}"
            f"{r['attacker_wins']:>9} ({100 * r['attacker_win_rate']:.0f}%){r['goes']:>6}{r['false_goes']:>6}{rate:<6}"
            f"{r['goes_really_open']:>13}{r['really_open_won']:>13}"
        )
