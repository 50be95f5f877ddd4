"""``bearcat solve ctf``, ``bearcat query ctf`` and ``bearcat play ctf``: the
1 vs 1 capture-the-flag game of thesis ch. 3 from the command line.

All three take the same game options and share the on-disk cache, so a game
is solved once and then queried and played in milliseconds.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict
from pathlib import Path

from bearcat.agents.cache import cache_root
from bearcat.agents.ground_station.ctf_cache import CtfGame, Solved, load_or_solve
from bearcat.agents.ground_station.guidance.methods import BUILTINS, Calibrated, WorstCase
from bearcat.cli import arguments
from bearcat.cli.output import Output, add_json_option
from bearcat.cli.progress import solve_bars
from bearcat.cli.writing import writing
from bearcat.maps import load_map
from bearcat.maps.ctf_rules import default_rules, unresolved_capture
from bearcat.maps.geodesy import bearing
from bearcat.solvers.ctf.playout import play
from bearcat.solvers.ctf.queries import CtfQueries, StateReport
from bearcat.solvers.ctf.sets import DEFAULT_TOL, SET_NAMES, STAGES
from bearcat.solvers.levelset.hji import SCHEMES

DEFAULT_GRID = 45


def add_game_options(parser: argparse.ArgumentParser) -> None:
    game = parser.add_argument_group("the game")
    game.add_argument(
        "--map", required=True, help="built-in map name or path to a GeoJSON map with flag and return regions"
    )
    game.add_argument(
        "--grid",
        type=int,
        default=DEFAULT_GRID,
        metavar="N",
        help=f"grid points per axis of each player's position (N^4 joint states; default {DEFAULT_GRID})",
    )
    game.add_argument(
        "--stages",
        choices=tuple(STAGES),
        default="both",
        help="return: R_A only; capture: F_A only; both: R_A and the two-stage W_A (default); all: R_A, F_A and W_A",
    )
    game.add_argument(
        "--scheme",
        choices=tuple(SCHEMES),
        default="weno5",
        help="weno5: WENO5 + RK3 (default, accurate); first: first-order upwind (fast, diffusive)",
    )
    game.add_argument(
        "--attacker-speed",
        type=arguments.positive,
        default=1.0,
        metavar="V",
        help="attacker top speed in m/s on full-speed terrain (default 1)",
    )
    game.add_argument(
        "--defender-speed",
        type=arguments.positive,
        default=1.0,
        metavar="V",
        help="defender top speed in m/s on full-speed terrain (default 1)",
    )
    game.add_argument(
        "--capture-radius",
        type=arguments.non_negative,
        metavar="R",
        help="capture radius in m (default: 5%% of the map's longer side, 0.5 on a 10 m arena)",
    )
    game.add_argument(
        "--capture-time",
        type=arguments.positive,
        metavar="T",
        help="time allowed for flag capture in s (default: 1.2 x the longer side / the slower speed)",
    )
    game.add_argument(
        "--return-time",
        type=arguments.positive,
        metavar="T",
        help="time allowed for flag return in s (default as --capture-time)",
    )
    game.add_argument(
        "--tol",
        type=arguments.positive,
        default=DEFAULT_TOL,
        metavar="CELLS",
        help=f"convergence tolerance in cells (default {DEFAULT_TOL})",
    )
    arguments.add_device_option(game)
    game.add_argument("--no-cache", action="store_true", help="solve afresh and store nothing")


def register(commands: arguments.Commands) -> None:
    """``solve ctf``, ``query ctf`` and ``play ctf``."""
    parser = commands.games("solve").add_parser(
        "ctf",
        help="1 vs 1 capture-the-flag: HJI winning sets, cached for queries",
        description="Solve the flag-return set R_A, the flag-capture set F_A or the two-stage winning set W_A "
        "(thesis 3.3) on a map and cache them on disk.",
    )
    add_game_options(parser)
    parser.add_argument(
        "--local",
        action="store_true",
        help="update only a narrow band around the front: the same sets and time-to-win, with the defender's "
        "margins clamped a few cells out (see the benchmarks page of the docs)",
    )
    add_json_option(parser, "a summary")
    parser.set_defaults(run=run_solve)

    q = commands.games("query").add_parser(
        "ctf",
        help="winner, margin, optimal headings and the opponent's winning region at a state",
        description="Guidance for the current positions, as the phones of thesis 3.5 showed it. "
        "Solves the game first if it is not cached.",
    )
    add_game_options(q)
    _add_state_options(q)
    q.add_argument(
        "--phase",
        choices=("capture", "return"),
        help="capture: the attacker has not taken the flag; return: it has (default: the first stage solved)",
    )
    q.add_argument("--plot", type=Path, metavar="PNG", help="draw the state and both players' opponent regions")
    robust = q.add_argument_group(
        "answers for stale, noisy fixes",
        "with --guidance worst-case or calibrated, each position is a fix taken some seconds ago. worst-case: "
        "the player is anywhere within its top speed x the fix's age plus the fix's error radius at the "
        "confidence, and the answers hold against all of it. calibrated: a tracker given the fix predicts the "
        "player to now; the attacker's go adds the margin 'bearcat calibrate' stored for the profile, and the "
        "defender's heading acts on a quantile of the value over the tracker's belief",
    )
    robust.add_argument(
        "--guidance",
        choices=tuple(BUILTINS),
        default="none",
        help="the built-in guidance method to answer with: none (default), the positions are exact; "
        "worst-case or calibrated: see above",
    )
    robust.add_argument(
        "--netem",
        default="wifi",
        metavar="PROFILE",
        help="calibrated: the profile whose GPS model the tracker uses and whose calibration is read (default wifi)",
    )
    robust.add_argument(
        "--alpha",
        type=float,
        default=0.01,
        metavar="A",
        help="calibrated: the share of goes allowed to be wrong, as calibrated (default 0.01)",
    )
    for who in ("attacker", "defender"):
        robust.add_argument(
            f"--{who}-age",
            type=arguments.non_negative,
            default=1.0,
            metavar="S",
            help=f"seconds since the {who}'s fix was taken (default 1)",
        )
    robust.add_argument(
        "--accuracy",
        type=arguments.non_negative,
        default=0.0,
        metavar="M",
        help="both fixes' GPS error, metres per axis at 1 sigma, as phones report it (default 0)",
    )
    robust.add_argument(
        "--confidence",
        type=_confidence,
        default=0.95,
        metavar="P",
        help="the share of the GPS error circle guarded against, in [0, 1) (default 0.95)",
    )
    add_json_option(q, "the answer")
    q.set_defaults(run=run_query)

    p = commands.games("play").add_parser(
        "ctf",
        help="both players follow the optimal strategies from a start state (thesis 3.4, Fig. 3.4-3.5)",
        description="Closed-loop simulation: each player follows the heading of eqs. 3.12-3.13, the attacker "
        "switching to the flag-return strategy once it holds the flag. Solves the game first if it is not cached.",
    )
    add_game_options(p)
    _add_state_options(p)
    p.add_argument("--plot", type=Path, metavar="PNG", help="draw the start's winning region and both tracks")
    add_json_option(p, "the tracks and outcome")
    p.set_defaults(run=run_play)


def _confidence(text: str) -> float:
    value = arguments.non_negative(text)
    if value >= 1.0:
        raise argparse.ArgumentTypeError(f"{text!r} is not below 1: no circle holds a Gaussian error for certain")
    return value


def _add_state_options(parser) -> None:
    parser.add_argument("--attacker", required=True, type=arguments.point, metavar="X,Y", help="attacker position (m)")
    parser.add_argument("--defender", required=True, type=arguments.point, metavar="X,Y", help="defender position (m)")


def game_from_args(args) -> CtfGame:
    game_map = load_map(args.map)
    rules = default_rules(
        game_map,
        args.attacker_speed,
        args.defender_speed,
        capture_radius=args.capture_radius,
        capture_time=args.capture_time,
        return_time=args.return_time,
    )
    if args.grid < 9:
        raise arguments.UsageError(f"--grid {args.grid} is too coarse; use at least 9 points per axis")
    coarse = unresolved_capture(game_map, args.grid, rules.capture_radius)
    if coarse is not None:
        raise arguments.UsageError(
            f"--grid {args.grid} is too coarse for a capture radius of {rules.capture_radius:g} m: its cells on "
            f"map {game_map.name} are {coarse[0]:.2f} m; use --grid {coarse[1]} or more, or a larger --capture-radius"
        )
    local = getattr(args, "local", False)  # only `solve ctf` offers it: guidance shows the full grid's margins
    return CtfGame(game_map, args.grid, rules, scheme=args.scheme, tol=args.tol, local=local, device=args.device)


def solve_game(args) -> tuple[CtfGame, Solved, float]:
    """Load or solve the game the options name, with a progress bar on stderr
    for sets being solved. Positions given on the command line are checked
    against the map first, so a typo costs no solve."""
    game = game_from_args(args)
    for who in ("attacker", "defender"):
        if getattr(args, who, None) is not None:
            game.map.check_position(getattr(args, who), who)
    progress = solve_bars()
    started = time.perf_counter()
    try:
        with writing(cache_root(), "cache directory"):
            solved = load_or_solve(game, args.stages, use_cache=not args.no_cache, progress=progress)
    finally:
        progress.close()
    return game, solved, time.perf_counter() - started


def set_summary(game: CtfGame, solved: Solved) -> list[dict]:
    rows = []
    free = solved.solution.geometry.free
    joint_free = free[:, :, None, None] & free[None, None, :, :]
    for name, found in solved.solution.sets.items():
        wins = (found.value <= 0) & joint_free
        rows.append(
            {
                "set": SET_NAMES[name],
                "attacker_wins_fraction": round(float(wins.sum() / joint_free.sum()), 4),
                "converged": found.converged,
                "converged_at_s": found.converged_at,
                "horizon_s": game.rules.return_time if name == "return" else game.rules.capture_time,
                "steps": found.steps,
                "node_updates": found.node_updates,
                "device": found.device,
                # A local solve's margins stop at its ceiling, the value's largest.
                "margin_ceiling_m": round(float(found.value.max()), 3) if game.local else None,
                "source": solved.sources[name],
                "file": str(solved.paths[name]) if name in solved.paths else None,
            }
        )
    return rows


def run_solve(args) -> int:
    out = Output(args.json)
    game, solved, seconds = solve_game(args)
    rules, n = game.rules, game.grid_points
    out.say(
        f"capture-the-flag on {game.map.name}: {n}^4 = {n**4:,} joint states, {game.scheme}"
        f"{' (local band)' if game.local else ''}, "
        f"speeds {rules.attacker_speed:g}/{rules.defender_speed:g} m/s, capture radius {rules.capture_radius:g} m"
    )
    rows = set_summary(game, solved)
    for row in rows:
        if row["source"] == "cache":
            how = "loaded from cache"
        elif row["converged"]:
            how = (
                f"converged at {row['converged_at_s']:.1f} s of game time, {row['steps']} steps, "
                f"{row['node_updates']:,} node updates on {row['device']}"
            )
        else:
            how = (
                f"still changing at {row['horizon_s']:g} s ({row['steps']} steps on {row['device']}): this is the "
                f"{row['horizon_s']:g} s game; longer stage times approach the unlimited one"
            )
        if row["margin_ceiling_m"] is not None:
            how += f"; defender margins clamped at {row['margin_ceiling_m']:g} m"
        out.say(
            f"{row['set']}: attacker wins from {100 * row['attacker_wins_fraction']:.1f}% of free joint states; {how}"
        )
    out.say(f"{seconds:.2f} s wall; cache {cache_root()}")
    out.json(
        {
            "map": game.map.name,
            "grid": n,
            "scheme": game.scheme,
            "local": game.local,
            "rules": asdict(rules),
            "sets": rows,
            "seconds": round(seconds, 3),
        },
    )
    return 0


def bearing_deg(heading) -> float | None:
    """Degrees clockwise from north, as the phones show a heading."""
    if heading is None:
        return None
    return round(bearing(heading[0], heading[1]), 2)


def run_query(args) -> int:
    out = Output(args.json)
    game, solved, _seconds = solve_game(args)
    guidance = CtfQueries(solved.solution)
    phase = args.phase or ("return" if args.stages == "return" else "capture")
    report = guidance.evaluate(args.attacker, args.defender, phase)
    method = BUILTINS[args.guidance]
    args.robust = method is WorstCase
    if args.robust:
        robust = robust_answers(args, game, guidance, phase)
        report = StateReport(report.value, robust["attacker"].heading, robust["defender"].heading)
        defender_values = robust["defender_region"]
        attacker_values = robust["attacker_region"]
    else:
        defender_values = guidance.defender_region_values(args.attacker, phase)
        attacker_values = guidance.attacker_region_values(args.defender, phase)
    defender_polygons = guidance.polygons(defender_values, "defender")
    attacker_polygons = guidance.polygons(attacker_values, "attacker")
    name = SET_NAMES[guidance.value_set(phase).name]
    answer = {
        "map": game.map.name,
        "phase": phase,
        "set": name,
        "attacker": list(args.attacker),
        "defender": list(args.defender),
        "winner": report.winner,
        "value_m": round(report.value, 4),
        "attacker_heading": _heading_json(report.attacker_heading),
        "defender_heading": _heading_json(report.defender_heading),
        "defender_region_area_m2": round(defender_polygons.area, 2),
        "attacker_region_area_m2": round(attacker_polygons.area, 2),
    }
    out.say(
        f"{report.winner} wins ({name}, {phase} phase): value {report.value:+.3f} m "
        f"({'attacker margin' if report.value <= 0 else 'defender margin'} {abs(report.value):.3f} m)"
    )
    if args.robust:
        answer["robust"] = _robust_json(robust)
        for side, verdict in (("attacker", "go"), ("defender", "winning")):
            a = robust[side]
            out.say(
                f"robust, {side}'s display (the set of radius {robust['radii'][side]:.2f} m round each fix): "
                f"worst case {a.worst:+.3f} m, {verdict if a.wins else 'no ' + verdict}"
                + (" - uncertain: the plain answer differs" if a.uncertain else "")
            )
    if method is Calibrated:
        calibrated = calibrated_answers(args, game, guidance, phase)
        answer["calibrated"] = calibrated
        a, d = calibrated["attacker"], calibrated["defender"]
        margin = "none: no go at this age" if a["margin_m"] is None else f"{a['margin_m']:+.3f} m"
        out.say(
            f"calibrated, attacker's display (predicted {calibrated['age_s']:g} s on): value {a['value_m']:+.3f} m, "
            f"margin {margin}, {'go' if a['go'] else 'no go'}" + (f" ({a['note']})" if a["note"] else "")
        )
        heading = "none" if d["heading_deg"] is None else f"{d['heading_deg']:.1f} deg from north"
        out.say(
            f"calibrated, defender's display: value {d['value_m']:+.3f} m at the {calibrated['defender_quantile']:g} "
            f"quantile of its belief, heading {heading}"
        )
    for who in ("attacker", "defender"):
        h = answer[f"{who}_heading"]
        text = "none (the value is flat here)" if h is None else f"{h['bearing_deg']:.1f} deg from north"
        out.say(f"{who} {'robust' if args.robust else 'optimal'} heading: {text}")
    out.say(
        f"defender's winning region for this attacker position: {answer['defender_region_area_m2']:.1f} m^2; "
        f"attacker's for this defender position: {answer['attacker_region_area_m2']:.1f} m^2"
        + (" (robust: where that side may win against some position in the other's set)" if args.robust else "")
    )
    if out.wants_json:
        answer["regions"] = {
            "defender": _polygons_json(defender_polygons),
            "attacker": _polygons_json(attacker_polygons),
        }
        out.json(answer)
    if args.plot is not None:
        from bearcat.figures.games import ctf_query_figure

        disks = robust["radii"] if args.robust else None
        fig = ctf_query_figure(
            game.map,
            guidance,
            args.attacker,
            args.defender,
            report,
            phase,
            defender_values,
            attacker_values,
            name,
            disks=disks,
        )
        out.figure(fig, args.plot, dpi=110)
    return 0


def robust_answers(args, game: CtfGame, guidance: CtfQueries, phase: str) -> dict:
    """Both displays' robust answers and regions for the fixes the options describe."""
    from bearcat.agents.ground_station.guidance.fixes import Uncertainty
    from bearcat.solvers.ctf.robust import RobustCtf

    rules = game.rules
    uncertainty = Uncertainty({"attacker": rules.attacker_speed, "defender": rules.defender_speed}, args.confidence)
    attacker_radius = uncertainty.radius("attacker", args.attacker_age, args.accuracy)
    defender_radius = uncertainty.radius("defender", args.defender_age, args.accuracy)
    assert attacker_radius is not None and defender_radius is not None  # both top speeds are known
    radii = {"attacker": attacker_radius, "defender": defender_radius}
    robust = RobustCtf(guidance)
    attacker = robust.cover("attacker", args.attacker, radii["attacker"])
    defender = robust.cover("defender", args.defender, radii["defender"])
    return {
        "radii": radii,
        "attacker": robust.answer("attacker", attacker, defender, phase),
        "defender": robust.answer("defender", attacker, defender, phase),
        "defender_region": robust.region_values("defender", attacker, phase),
        "attacker_region": robust.region_values("attacker", defender, phase),
    }


def calibrated_answers(args, game: CtfGame, guidance: CtfQueries, phase: str) -> dict:
    """Both displays' calibrated answers for the fixes the options describe:
    a tracker per player given its fix, predicted to the moment the older is
    its age old."""
    from bearcat.agents.ground_station.calibration_store import load_calibration
    from bearcat.agents.ground_station.guidance.ctf import CtfAdvisor, Estimate
    from bearcat.agents.ground_station.tracker import Motion, Tracker
    from bearcat.netem.profiles import load_profile

    if not 0.0 < args.alpha <= 0.5:
        raise arguments.UsageError(f"--alpha must lie in (0, 0.5], got {args.alpha:g}")
    profile = load_profile(args.netem)
    rules = game.rules
    now = max(args.attacker_age, args.defender_age)
    beliefs = {}
    for who, speed in (("attacker", rules.attacker_speed), ("defender", rules.defender_speed)):
        tracker = Tracker(profile.gps, profile.compass, Motion.of(speed))
        tracker.observe(now - getattr(args, f"{who}_age"), getattr(args, who), args.accuracy or None)
        belief = tracker.predict(now)
        assert belief is not None  # the tracker has its fix
        beliefs[who] = belief
    calibration = load_calibration(game, profile, args.alpha)
    advisor = CtfAdvisor(
        game.map,
        guidance,
        attacker="attacker",
        defender="defender",
        phase=phase,
        calibration=lambda: calibration,
        alpha=args.alpha,
    )
    estimate = Estimate(now, beliefs["attacker"], beliefs["defender"], now)
    attacker, defender = (advisor.calibrated_answer(side, estimate) for side in ("attacker", "defender"))
    return {
        "profile": profile.name,
        "alpha": args.alpha,
        "calibrated": calibration is not None,
        "age_s": now,
        "defender_quantile": advisor.defender_quantile,
        "attacker": {
            "value_m": round(attacker["value"], 4),
            "margin_m": attacker["margin"],
            "go": attacker["go"],
            "heading_deg": attacker["heading"],
            "note": attacker.get("note", ""),
        },
        "defender": {"value_m": round(defender["value"], 4), "heading_deg": defender["heading"]},
    }


def _robust_json(robust: dict) -> dict:
    return {
        side: {
            "radius_m": round(robust["radii"][side], 3),
            "worst_value_m": round(robust[side].worst, 4),
            "wins": robust[side].wins,
            "uncertain": robust[side].uncertain,
            "heading": _heading_json(robust[side].heading),
        }
        for side in ("attacker", "defender")
    }


def run_play(args) -> int:
    out = Output(args.json)
    game, solved, _ = solve_game(args)
    guidance = CtfQueries(solved.solution)
    outcome = play(guidance, args.attacker, args.defender)
    start = guidance.evaluate(args.attacker, args.defender, outcome.phases[0])
    out.say(f"start: value {start.value:+.3f} m, {start.winner} predicted to win")
    flag = "" if outcome.flag_time is None else f", flag taken at {outcome.flag_time:.2f} s"
    out.say(f"{outcome.winner} won ({outcome.reason}) after {outcome.duration:.2f} s{flag}")
    out.json(
        {
            "map": game.map.name,
            "predicted_winner": start.winner,
            "value_m": round(start.value, 4),
            "winner": outcome.winner,
            "reason": outcome.reason,
            "duration_s": round(outcome.duration, 3),
            "flag_time_s": None if outcome.flag_time is None else round(outcome.flag_time, 3),
            "times_s": [round(float(t), 3) for t in outcome.times],
            "attacker": [[round(float(x), 3), round(float(y), 3)] for x, y in outcome.attacker],
            "defender": [[round(float(x), 3), round(float(y), 3)] for x, y in outcome.defender],
        },
    )
    if args.plot is not None:
        from bearcat.figures.games import ctf_play_figure

        fig = ctf_play_figure(game.map, guidance, outcome, start)
        out.figure(fig, args.plot, dpi=110)
    return 0


def _heading_json(heading) -> dict | None:
    if heading is None:
        return None
    return {"east": round(heading[0], 5), "north": round(heading[1], 5), "bearing_deg": bearing_deg(heading)}


def _polygons_json(shape) -> list:
    """Outer ring and holes of each polygon, in map metres."""
    return [
        [[[round(x, 3), round(y, 3)] for x, y in ring.coords] for ring in (p.exterior, *p.interiors)]
        for p in shape.geoms
    ]
