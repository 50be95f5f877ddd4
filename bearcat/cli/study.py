"""``bearcat study fake-out|holding|go-no-go|search``: batches of simulated
games, resumable, with a table and a figure at the end (``DIR/results.jsonl``
per game, ``DIR/summary.json``, ``DIR/STUDY.png``).

``--cluster tcp://HOST:PORT`` plays the games on a Dask cluster instead of
this machine's cores, with the same results file and the same results: each
game carries its seed, and each worker solves or loads the scenario's sets
in its own machine's cache.

``--human defender`` plays the study's games live instead, one after the
other, with a person driving the defender from the keyboard; each game is
appended to the same results file, under its own labels, so people's results
sit beside the models' in the same table.
"""

from __future__ import annotations

import json
from pathlib import Path

from bearcat.cli import arguments
from bearcat.cli.arguments import Commands
from bearcat.cli.output import Output
from bearcat.cli.progress import counting
from bearcat.cli.writing import make_directory, writing
from bearcat.scenarios.schema import TRANSPORTS, Scenario, ScenarioError
from bearcat.studies.thesis import ABLATED, GUIDANCE, STUDIES


def register(commands: Commands) -> None:
    p = commands.add_parser(
        "study",
        description=" ".join(f"{name}: {study.description}." for name, study in STUDIES.items()),
    )
    p.add_argument("study", choices=tuple(STUDIES))
    p.add_argument("--trials", type=int, default=200, metavar="N", help="games per cell and profile (default 200)")
    p.add_argument("--seed", type=arguments.seed, default=0, metavar="S", help="seed of the first game (default 0)")
    p.add_argument("--netem", nargs="+", metavar="PROFILE", help="profiles to play on (default: the study's)")
    p.add_argument(
        "--transport",
        nargs="+",
        choices=TRANSPORTS,
        help="transports to compare (default: each scenario's own): tcp, udp or both",
    )
    p.add_argument(
        "--guidance",
        nargs="+",
        choices=(*GUIDANCE, *ABLATED),
        metavar="NAME",
        help=f"play only the cells of this guidance: {', '.join(map(repr, GUIDANCE))} (default: each of these), "
        "or calibrated guidance with a part switched off: " + ", ".join(map(repr, ABLATED)),
    )
    p.add_argument(
        "--rate",
        nargs="+",
        type=float,
        metavar="HZ",
        help="play only the cells of these report rates (holding, fake-out; default: every one)",
    )
    p.add_argument(
        "--search",
        nargs="+",
        type=arguments.plugin,
        metavar="POLICY",
        help="the search study: play these UAV tasking policies, built-in or one's own (a name, module:attribute "
        "or file.py:attribute), instead of reachability, lawnmower and nearest",
    )
    p.add_argument(
        "--vary",
        action="append",
        type=arguments.change,
        metavar="KEY=VALUE",
        help="change a scenario key in every game, as a variant does (a TOML value; repeatable), such as "
        "'agent.attacker.behaviour=\"mine.py:Mine\"' to play a behaviour of one's own in the study; "
        "a file named there is relative to this folder",
    )
    arguments.add_batch_options(p, "games")
    p.add_argument("--out", type=Path, metavar="DIR", help="results directory (default ./studies/STUDY)")
    p.add_argument(
        "--human",
        choices=("defender",),
        help="a person plays this side from the keyboard, live, in the study's scenario (fake-out)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print the table's rows (DIR/summary.json) as JSON and nothing else on stdout (the table goes to stderr)",
    )
    p.set_defaults(run=run)


def run(args) -> int:
    from bearcat.netem.profiles import load_profile
    from bearcat.studies.batch import read_results, run_batch
    from bearcat.studies.thesis import play_task, study_tasks, unplayable

    for profile in args.netem or ():
        load_profile(profile)
    if args.trials < 1:
        raise arguments.UsageError("--trials must be at least 1")
    if args.human is not None and args.study != "fake-out":
        raise arguments.UsageError(f"--human plays the fake-out study; {args.study} has no human side")
    if args.human is not None and args.cluster is not None:
        raise arguments.UsageError("--human plays its games live on this machine; it takes no --cluster")
    arguments.check_seeds(args.seed, args.trials)
    _check_guidance(args.study, args.guidance)
    _check_rates(args.study, args.rate)
    if args.search and args.study != "search":
        raise arguments.UsageError(f"--search picks the search study's tasking policies; {args.study} flies no UAV")
    report = Output(args.json)
    out = args.out or Path("studies") / args.study
    make_directory(out, "results directory")
    if args.cluster is None:
        _presolve(STUDIES[args.study])
    else:
        report.say(f"playing on the Dask cluster at {args.cluster}; each machine solves the sets on its first game")
    with writing(out, "results directory"):
        if args.human is not None:
            from bearcat.studies.human_trials import play_human_trials

            play_human_trials(out, args.human, args.trials, args.seed, say=report.say)
            results = read_results(out / "results.jsonl")  # the models' games beside the person's
        else:
            changes = dict(args.vary or ())
            tasks = study_tasks(
                args.study,
                args.trials,
                args.seed,
                args.netem,
                args.transport,
                args.guidance,
                args.rate,
                changes,
                args.search,
            )
            why = unplayable(tasks)
            if why is not None:
                raise ScenarioError(why)
            for line in uncalibrated(tasks):
                report.say(line)
            with counting(len(tasks), args.study, "game") as finished:
                results = run_batch(
                    tasks,
                    play_task,
                    out / "results.jsonl",
                    workers=args.workers,
                    scheduler=args.cluster,
                    on_result=finished,
                    preflight=unplayable,
                )
            wanted = {t["key"] for t in tasks}
            results = {k: r for k, r in results.items() if k in wanted}
        rows = summary_rows(args.study, results.values())
        (out / "summary.json").write_text(json.dumps(rows, indent=2) + "\n")
    report.say(TABLES[args.study](rows))
    report.say(f"per-game results in {out}/results.jsonl; replay one with bearcat simulate SCENARIO --seed S --netem P")
    from bearcat.figures.studies import FIGURES

    report.figure(FIGURES[args.study](rows), out / f"{args.study}.png", dpi=110)
    report.json(rows)
    return 0


def _check_guidance(study: str, guidance) -> None:
    """Each guidance asked for is one ``study`` varies."""
    from bearcat.studies.thesis import study_guidance

    offered = study_guidance(study)
    for name in guidance or ():
        if name not in offered:
            has = ", ".join(map(repr, offered)) or "none: it varies no guidance"
            raise arguments.UsageError(f"--guidance {name!r}: the {study} study has no such cells; it has {has}")


def _check_rates(study: str, rates) -> None:
    """Each report rate asked for is one ``study`` varies."""
    from bearcat.studies.thesis import study_rates

    offered = study_rates(study)
    for rate in rates or ():
        if rate not in offered:
            has = ", ".join(f"{r:g}" for r in offered) + " Hz" if offered else "none: it varies no report rate"
            raise arguments.UsageError(f"--rate {rate:g}: the {study} study has no such cells; its rates are {has}")


def _presolve(study) -> None:
    """Solve each scenario's game once here, with progress bars, so the
    local worker processes only load it. A cluster's workers have no use
    for this machine's cache: each solves a game on its first game of it,
    or loads it from its own machine's cache, one worker at a time per
    machine (``ctf_cache.load_or_solve``)."""
    from bearcat.cli.presolve import presolve
    from bearcat.scenarios.schema import load_scenario

    for name in dict.fromkeys(cell.scenario for cell in study.cells):
        scenario = load_scenario(name)
        presolve(scenario, scenario.netem)


def uncalibrated(tasks) -> list[str]:
    """A line for each scenario and profile whose calibrated attackers will
    have no calibration to answer from, naming the command that makes one."""
    from bearcat.agents.ground_station.calibration_store import calibrate_command, load_calibration
    from bearcat.agents.ground_station.guidance.methods import Calibrated
    from bearcat.agents.ground_station.tracker import TRACKER_ABLATIONS
    from bearcat.netem.profiles import load_profile
    from bearcat.scenarios.cast import ctf_of, is_ctf
    from bearcat.scenarios.schema import load_scenario
    from bearcat.scenarios.variants import vary

    cells = {(t["scenario"], t["netem"], json.dumps(t.get("changes") or {}, sort_keys=True)) for t in tasks}
    wanted: dict[tuple, Scenario] = {}
    for name, netem, changes in sorted(cells, key=str):
        scenario = vary(load_scenario(name), json.loads(changes))
        attacker = scenario.team("attacker")[0].id
        calibrated = is_ctf(scenario) and scenario.guidance_of(attacker).entry.factory is Calibrated
        if calibrated and "calibration" not in scenario.ablate:
            tracker = tuple(sorted(set(scenario.ablate) & set(TRACKER_ABLATIONS)))
            wanted.setdefault((name, netem, tracker), scenario)
    lines = []
    for (name, netem, _), scenario in wanted.items():
        profile = load_profile(netem or scenario.netem)
        if load_calibration(ctf_of(scenario).own(), profile, scenario.alpha, scenario.ablate) is None:
            lines.append(
                f"no calibration of {name} on {profile.name}: its calibrated attackers take the tracker's own margin "
                f"({calibrate_command(name, profile.name, scenario.ablate)} makes one)"
            )
    return lines


def summary_rows(study: str, results) -> list[dict]:
    from bearcat.studies.thesis import summarise, summarise_search

    if study == "search":
        return summarise_search(results)
    return summarise(results, STUDIES[study].by)


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


def _rate(count: int, games: int, interval) -> str:
    low, high = interval
    return f"{count}/{games} {100 * count / games:.0f}% ({100 * low:.0f}-{100 * high:.0f})"


def _goes_table(rows) -> str:
    w = max(len("guidance"), *(len(r["guidance"]) for r in rows)) + 2
    lines = [
        f"{'guidance':<{w}}{'network':<17}{'attacker wins (95%)':>24}{'goes':>6}{'false goes (95%)':>24}"
        f"{'caught':>8}{'timed out':>11}{'really open':>13}{'of them won':>13}"
    ]
    for r in rows:
        false = "-" if not r["goes"] else _rate(r["false_goes"], r["goes"], r["false_go_interval"])
        lines.append(
            f"{r['guidance']:<{w}}{r['netem'] + '/' + r['transport']:<17}"
            f"{_rate(r['attacker_wins'], r['games'], r['attacker_win_interval']):>24}{r['goes']:>6}{false:>24}"
            f"{r['false_goes_caught']:>8}{r['false_goes_out_of_time']:>11}"
            f"{r['goes_really_open']:>13}{r['really_open_won']:>13}"
        )
    return "\n".join(lines)


def _holding_table(rows) -> str:
    guidance = list(dict.fromkeys(r["guidance"] for r in rows))
    w = max(26, *(len(g) + 2 for g in guidance))
    lines = [f"{'network':<17}{'report Hz':>10}" + "".join(f"{g:>{w}}" for g in guidance)]
    cells = {(r["netem"] + "/" + r["transport"], r["rate"], r["guidance"]): r for r in rows}
    for network, rate in dict.fromkeys((n, h) for n, h, _ in cells):
        line = f"{network:<17}{rate:>10g}"
        for g in guidance:
            r = cells.get((network, rate, g))
            line += f"{'-' if r is None else _rate(r['defender_wins'], r['games'], r['defender_win_interval']):>{w}}"
        lines.append(line)
    return "defender holds (defender wins, 95% interval)\n" + "\n".join(lines)


def _fake_out_table(rows) -> str:
    people = [r for r in rows if r["defender"] == "human"]
    rows = [r for r in rows if r["defender"] != "human"]
    reactions = sorted({r["reaction"] for r in rows})
    lines = ["attacker wins (95% interval) by the defender's reaction time (s)"]
    for rate in sorted({r["rate"] for r in rows}):
        lines.append(f"phones reporting at {rate:g} Hz")
        lines.append(f"{'defender':<26}" + "".join(f"{t:>20g}" for t in reactions))
        at_rate = [r for r in rows if r["rate"] == rate]
        for defender, marking in dict.fromkeys((r["defender"], r["marking"]) for r in at_rate):
            name = defender if marking is None else f"{defender}, marks {marking:g} m"
            line = f"{name:<26}"
            mine = {r["reaction"]: r for r in at_rate if (r["defender"], r["marking"]) == (defender, marking)}
            for t in reactions:
                r = mine.get(t)
                line += f"{'-' if r is None else _rate(r['attacker_wins'], r['games'], r['attacker_win_interval']):>20}"
            lines.append(line)
    for r in people:
        won = _rate(r["attacker_wins"], r["games"], r["attacker_win_interval"])
        lines.append(f"a person as the defender, phones at {r['rate']:g} Hz: attacker wins {won}")
    return "\n".join(lines)


TABLES = {"fake-out": _fake_out_table, "holding": _holding_table, "go-no-go": _goes_table, "search": _search_table}
