"""``bearcat calibrate SCENARIO --netem PROFILE``: measure the margin
calibrated guidance adds to its value, on simulated games
(``studies.calibration``), check it on games it never saw, and store it in
the cache where the ground station finds it.

Written to ``--out DIR`` (default ``./calibrations/SCENARIO-PROFILE``):
``scores.jsonl`` (one line per game, resumable), ``calibration.json`` (what
the cache holds), ``coverage.json`` (the held-out check per bin) and
``calibration.png`` (the errors by report age, with the margins).
"""

from __future__ import annotations

import json
from pathlib import Path

from bearcat.cli import arguments
from bearcat.cli.arguments import Commands
from bearcat.cli.output import Output
from bearcat.cli.progress import counting
from bearcat.cli.writing import make_directory, writing


def register(commands: Commands) -> None:
    from bearcat.agents.ground_station.tracker import TRACKER_ABLATIONS
    from bearcat.studies.calibration import CALIBRATION_SEED

    p = commands.add_parser(
        "calibrate",
        description="Plays simulated games of a capture-the-flag scenario on a network profile, scores the value "
        "calibrated guidance would use against the value at the true positions, and stores, per phase and report "
        "age, the margin that bounds the share of wrong goes by --alpha; then checks that bound on games it never saw.",
    )
    p.add_argument("scenario", metavar="SCENARIO", help="a built-in capture-the-flag scenario or a scenario TOML file")
    p.add_argument("--netem", metavar="PROFILE", help="network profile (default: the scenario's)")
    p.add_argument("--trials", type=arguments.count, default=200, metavar="N", help="games to fit on (default 200)")
    p.add_argument("--holdout", type=arguments.count, default=100, metavar="M", help="games to check on (default 100)")
    p.add_argument(
        "--seed",
        type=arguments.seed,
        default=CALIBRATION_SEED,
        metavar="S",
        help=f"seed of the first game (default {CALIBRATION_SEED}, apart from every study's seeds); "
        "the check plays the seeds after the fit's",
    )
    p.add_argument(
        "--ablate",
        action="append",
        default=[],
        choices=TRACKER_ABLATIONS,
        metavar="PART",
        help="calibrate trackers with this part switched off, for a study's guidance.ablate (repeatable): "
        + ", ".join(TRACKER_ABLATIONS),
    )
    p.add_argument(
        "--alpha",
        type=float,
        metavar="A",
        help="the share of goes allowed to be wrong (default: the scenario's guidance.alpha)",
    )
    arguments.add_batch_options(p, "games")
    p.add_argument(
        "--out", type=Path, metavar="DIR", help="results directory (default ./calibrations/SCENARIO-PROFILE)"
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print the check (DIR/coverage.json) as JSON and nothing else on stdout (the table goes to stderr)",
    )
    p.set_defaults(run=run)


def run(args) -> int:
    from bearcat.agents.ground_station.calibration import coverage, fit
    from bearcat.agents.ground_station.calibration_store import store_calibration
    from bearcat.netem.profiles import load_profile
    from bearcat.scenarios.cast import ctf_of, is_ctf
    from bearcat.scenarios.schema import load_scenario
    from bearcat.scenarios.variants import vary
    from bearcat.studies.batch import run_batch
    from bearcat.studies.calibration import calibration_tasks, play_calibration_task, scores_of

    ablate = sorted(set(args.ablate))
    scenario = vary(load_scenario(args.scenario), {"guidance.ablate": ablate} if ablate else {})
    if not is_ctf(scenario):
        raise arguments.UsageError(
            f"{scenario.source}: calibrated guidance is for capture-the-flag, not {scenario.game}"
        )
    profile = load_profile(args.netem or scenario.netem)
    alpha = scenario.alpha if args.alpha is None else args.alpha
    if not 0.0 < alpha <= 0.5:
        raise arguments.UsageError(f"--alpha must lie in (0, 0.5], got {alpha:g}")
    arguments.check_seeds(args.seed, args.trials + args.holdout)
    report = Output(args.json)
    out = args.out or Path("calibrations") / "-".join([scenario.name, profile.name, *(f"no-{a}" for a in ablate)])
    make_directory(out, "results directory")
    fitted = calibration_tasks(args.scenario, profile.name, args.seed, args.trials, "fit", ablate)
    checked = calibration_tasks(args.scenario, profile.name, args.seed + args.trials, args.holdout, "check", ablate)
    if args.cluster is None:
        from bearcat.cli.presolve import presolve

        presolve(scenario, profile.name)
    with writing(out, "results directory"):
        with counting(len(fitted) + len(checked), "calibration", "game") as finished:
            results = run_batch(
                fitted + checked,
                play_calibration_task,
                out / "scores.jsonl",
                workers=args.workers,
                scheduler=args.cluster,
                on_result=finished,
            )
        fit_scores = [s for t in fitted for s in scores_of(results[t["key"]])]
        check_scores = [s for t in checked for s in scores_of(results[t["key"]])]
        game = ctf_of(scenario).own()
        about = {
            "scenario": scenario.name,
            "map": scenario.map.name,
            "profile": profile.name,
            "ablate": ablate,
            "fit_seeds": [args.seed, args.seed + args.trials - 1],
            "check_seeds": [args.seed + args.trials, args.seed + args.trials + args.holdout - 1],
        }
        calibration = fit(fit_scores, alpha, about=about)
        checks = coverage(calibration, fit_scores, check_scores)
        rows = [_row(c) for c in checks]
        (out / "calibration.json").write_text(json.dumps(calibration.to_json(), indent=1) + "\n")
        (out / "coverage.json").write_text(json.dumps(rows, indent=1) + "\n")
        stored = store_calibration(calibration, game, profile, scenario.ablate)
    report.say(_table(rows, alpha))
    report.say(
        f"{len(fit_scores)} answers of {args.trials} games fitted (seeds {about['fit_seeds'][0]}-"
        f"{about['fit_seeds'][1]}); {len(check_scores)} answers of {args.holdout} others checked (seeds "
        f"{about['check_seeds'][0]}-{about['check_seeds'][1]})"
    )
    report.say(f"calibration stored in {stored}; per-game scores in {out}/scores.jsonl")
    from bearcat.figures.calibration import calibration_figure

    report.figure(calibration_figure(fit_scores, calibration), out / "calibration.png", dpi=110)
    report.json(rows)
    return 0


def _row(check) -> dict:
    return {
        "phase": check.phase,
        "ages": [check.ages[0], None if check.ages[1] == float("inf") else check.ages[1]],
        "margin": None if check.margin is None else round(check.margin, 4),
        "scores": check.scores,
        "games": check.games,
        "covered": check.covered,
        "coverage": None if check.share is None else round(check.share, 4),
        "interval": None if check.interval is None else [round(x, 4) for x in check.interval],
        "verdict": check.verdict,
    }


def _table(rows, alpha: float) -> str:
    lines = [
        f"margins at alpha {alpha:g}, and their coverage on held-out games (promised {1 - alpha:.1%})",
        f"{'phase':<9}{'report age, s':>14}{'margin, m':>11}{'answers':>9}{'games':>7}{'coverage':>10}"
        f"{'95% interval':>18}  verdict",
    ]
    for r in rows:
        low, high = r["ages"]
        ages = f"{low:g}-{high:g}" if high is not None else f"{low:g}+"
        margin = "none" if r["margin"] is None else f"{r['margin']:.2f}"
        share = "-" if r["coverage"] is None else f"{r['coverage']:.1%}"
        interval = "-" if r["interval"] is None else f"{r['interval'][0]:.1%}-{r['interval'][1]:.1%}"
        verdict = r["verdict"] or ("no margin: no go" if r["margin"] is None else "no held-out answers")
        lines.append(
            f"{r['phase']:<9}{ages:>14}{margin:>11}{r['scores']:>9}{r['games']:>7}{share:>10}{interval:>18}  {verdict}"
        )
    return "\n".join(lines)
