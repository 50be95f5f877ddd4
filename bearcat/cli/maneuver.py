"""``bearcat solve maneuver`` and ``bearcat play maneuver``: maneuvers
designed with reach-avoid sets (thesis 6.1), the quadrotor backflip first.

``solve`` computes the sets of a maneuver file (cached on disk as the
capture-the-flag sets are) and says whether each sequencing condition holds;
it exits 1 when one does not, so a script can stop a design that fails.
``play`` flies the design many times under random disturbances, switching by
the sets and, as a baseline, at fixed times, and at disturbances beyond the
design's bounds.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from bearcat.agents.cache import cache_root
from bearcat.cli import arguments
from bearcat.cli.output import Output, add_json_option
from bearcat.cli.progress import counting, solve_bars
from bearcat.cli.writing import writing
from bearcat.scenarios.maneuvers import Maneuver, list_maneuvers, load_maneuver, load_or_design, with_torque_share
from bearcat.solvers.levelset.hji import SCHEMES
from bearcat.solvers.maneuvers.backflip import BackflipSets
from bearcat.solvers.maneuvers.backflip_flight import Trials, fly_many, nominal_flight
from bearcat.solvers.maneuvers.planar_quad import DRIFT, IMPULSE, RECOVERY
from bearcat.studies.thesis import wilson

SET_LABELS = {
    "Reach_T4(T1)": "the turn-off's forward reach Reach_T4(T1)",
    "drift time": "the longest drift (turn-off and drift in (phi, phi', a))",
    "K2": "K2, unsafe to start the recovery (y, y', time)",
    "K1": "K1, unsafe to start the drift",
}
DEFAULT_SCALES = (1.0, 1.5, 2.0)


def _maneuver_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "maneuver", metavar="MANEUVER", help=f"a built-in maneuver ({', '.join(list_maneuvers())}) or a maneuver file"
    )
    parser.add_argument(
        "--torque-share",
        type=_share,
        metavar="S",
        help="the share of the thrust noise that turns the vehicle, in place of the file's (1 = the thesis's 5 %% "
        "as a worst-case torque)",
    )
    parser.add_argument("--scheme", choices=tuple(SCHEMES), default="weno5", help="the HJI scheme (default weno5)")
    arguments.add_device_option(parser)
    parser.add_argument("--no-cache", action="store_true", help="solve afresh and store nothing")


def register(commands: arguments.Commands) -> None:
    """``solve maneuver`` and ``play maneuver``."""
    parser = commands.games("solve").add_parser(
        "maneuver",
        help="a maneuver's capture and avoid sets and its sequencing checks (thesis 6.1)",
        description="Solve the capture sets RA_T(T_k) of each mode, the forward reach of the motors' turn-off "
        "and the unsafe sets K1-K3, and check that the modes chain (thesis 6.1.3). Exits 1 if a check fails.",
    )
    _maneuver_options(parser)
    parser.add_argument("--plot", type=Path, metavar="PNG", help="draw Figs. 6.2 and 6.3: the sets of both planes")
    add_json_option(parser, "the checks and horizons")
    parser.set_defaults(run=run_solve)

    parser = commands.games("play").add_parser(
        "maneuver",
        help="fly a designed maneuver many times, switching by its sets and at fixed times",
        description="Fly the full planar model of eq. 6.3 under random disturbances, switching modes as the "
        "sets allow and, as a baseline, at the times of the nominal flip; at the design's disturbance bound and "
        "beyond it.",
    )
    _maneuver_options(parser)
    parser.add_argument(
        "--trials", type=arguments.count, default=200, metavar="N", help="flips per policy and scale (default 200)"
    )
    parser.add_argument(
        "--scale",
        type=arguments.positive,
        nargs="+",
        default=list(DEFAULT_SCALES),
        metavar="X",
        help="disturbances as multiples of the design's bounds (default 1 1.5 2)",
    )
    parser.add_argument("--seed", type=arguments.seed, default=0, help="the seed of the disturbances (default 0)")
    parser.add_argument(
        "--plot", type=Path, metavar="PNG", help="draw flips at the first scale over the sets (Fig. 6.6a)"
    )
    add_json_option(parser, "the rates and the nominal flip")
    parser.set_defaults(run=run_play)


def run_solve(args) -> int:
    out = Output(args.json)
    maneuver, sets, source, seconds = _design(args)
    out.say(_heading(maneuver, sets, args.scheme))
    how = "loaded from the cache" if source == "cache" else f"solved in {seconds:.1f} s"
    out.say(f"sets {how} ({cache_root() / 'maneuver'})")
    for check in sets.checks:
        out.say(f"  {'holds ' if check.holds else 'FAILS '} {check}")
    out.say(
        f"turn-off: the impulse leaves {sets.turn_off[0]:.1f} to {sets.turn_off[1]:.1f} rad/s^2, decaying at "
        f"alpha = {sets.alpha:.0f} rad/s^3 (eq. 6.6)"
    )
    times = sets.times
    out.say(
        f"horizons: impulse {times['impulse']:g} s, turn-off {times['turn-off']:g} s, longest drift "
        f"{times['drift']:.2f} s, longest recovery {times['recovery']:.2f} s"
    )
    if args.plot:
        from bearcat.figures.maneuvers import design_figure

        out.figure(design_figure(sets), args.plot, dpi=120)
    out.json(_solve_report(maneuver, sets, source))
    if not sets.holds:
        out.say("the design does not hold: the failing condition above has no guarantee behind it")
        return 1
    return 0


def run_play(args) -> int:
    out = Output(args.json)
    maneuver, sets, source, _seconds = _design(args)
    out.say(_heading(maneuver, sets, args.scheme))
    if not sets.holds:
        failing = "; ".join(str(c) for c in sets.checks if not c.holds)
        out.say(f"warning: the design does not hold ({failing}); the flips below carry no guarantee")
    nominal = nominal_flight(sets, maneuver.start_height)
    impulse, drift, recovery = (float(t) for t in nominal.switches[:, 0])
    times = (impulse, drift, recovery)
    spent = nominal.time_in_mode
    out.say(
        f"nominal flip (no disturbance): climb {spent[0]:.2f} s, impulse {spent[1]:.2f} s, drift {spent[2]:.2f} s, "
        f"recovery {spent[3]:.2f} s (thesis Table 6.1: impulse 0.50-0.55, drift 0.55-0.61, recovery 2.56-5.54)"
    )
    rows = []
    kept = None
    with counting(2 * len(args.scale) * args.trials, "flying", "flips") as done:
        for scale in args.scale:
            for policy in ("sets", "timed"):
                trials = fly_many(
                    sets,
                    policy,
                    args.trials,
                    args.seed,
                    scale=scale,
                    times=times,
                    start_height=maneuver.start_height,
                    done=done,
                )
                rows.append(_row(trials))
                if kept is None:
                    kept = trials.flights
    out.say(f"{'disturbance':>12}  {'switching':<10} {'reached T3':>26}  {'touched unsafe set':>26}")
    for row in rows:
        out.say(
            f"{row['scale']:>10.2g} x  {row['policy']:<10} {_rate(row['reached'], row['reached_95'])}  "
            f"{_rate(row['unsafe'], row['unsafe_95'])}"
        )
    out.say(
        f"{args.trials} flips each; 95 % Wilson intervals. The guarantee covers only 1 x with the sets: beyond it, "
        "and for fixed times, these rates are what the runs show."
    )
    if args.plot:
        from bearcat.figures.maneuvers import design_figure

        out.figure(design_figure(sets, kept), args.plot, dpi=120)
    out.json(
        {
            **_solve_report(maneuver, sets, source),
            "trials": args.trials,
            "seed": args.seed,
            "nominal": {
                "switch_times_s": [round(t, 3) for t in times],
                "time_in_mode_s": {mode: round(t, 3) for mode, t in zip(MODES, spent)},
            },
            "rates": rows,
        }
    )
    return 0


MODES = ("climb", "impulse", "drift", "recovery")


def _design(args) -> tuple[Maneuver, BackflipSets, str, float]:
    maneuver = load_maneuver(args.maneuver)
    if args.torque_share is not None:
        maneuver = with_torque_share(maneuver, args.torque_share)
    progress = solve_bars(lambda name: f"solving {SET_LABELS.get(name, name)}", change_unit="", clock="horizon")
    started = time.perf_counter()
    try:
        with writing(cache_root(), "cache directory"):
            sets, source = load_or_design(
                maneuver, scheme=args.scheme, use_cache=not args.no_cache, progress=progress, device=args.device
            )
    finally:
        progress.close()
    return maneuver, sets, source, time.perf_counter() - started


def _heading(maneuver: Maneuver, sets: BackflipSets, scheme: str) -> str:
    b = sets.design
    a, v = b.attitude_grid.shape, b.vertical_grid.shape
    return (
        f"{maneuver.name} ({maneuver.source}): attitude grid {a[0]}x{a[1]}, height grid {v[0]}x{v[1]}, {scheme}; "
        f"disturbing torque up to {b.torque_bound(IMPULSE):.2f}, {b.torque_bound(DRIFT):.2f} and "
        f"{b.torque_bound(RECOVERY):.2f} rad/s^2 in the impulse, drift and recovery"
    )


def _solve_report(maneuver: Maneuver, sets: BackflipSets, source: str) -> dict:
    return {
        "maneuver": maneuver.name,
        "source": source,
        "holds": sets.holds,
        "checks": [
            {"inner": c.inner, "outer": c.outer, "holds": c.holds, "outside_share": c.outside, "worst": c.worst}
            for c in sets.checks
        ],
        "turn_off_rad_s2": list(sets.turn_off),
        "alpha_rad_s3": sets.alpha,
        "horizons_s": sets.times,
        "torque_share": sets.design.torque_share,
    }


def _row(trials: Trials) -> dict:
    return {
        "scale": trials.scale,
        "policy": trials.policy,
        "trials": trials.trials,
        "reached": round(trials.reached / trials.trials, 4),
        "reached_95": [round(x, 4) for x in wilson(trials.reached, trials.trials)],
        "unsafe": round(trials.unsafe / trials.trials, 4),
        "unsafe_95": [round(x, 4) for x in wilson(trials.unsafe, trials.trials)],
    }


def _rate(share: float, interval: list[float]) -> str:
    return f"{100 * share:5.1f} % [{100 * interval[0]:5.1f}, {100 * interval[1]:5.1f}]"


def _share(text: str) -> float:
    value = arguments.positive(text)
    if value > 1:
        raise argparse.ArgumentTypeError(f"{text!r} is above 1: no more than the whole noise can turn the vehicle")
    return value
