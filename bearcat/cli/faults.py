"""``bearcat faults``: run a fault-injection suite and say which invariants held.

Every case of the suite (a scenario, a fault plan, seeds) is run, in
virtual time or live, into ``OUT/CASE/seed-S``; the run checker judges each
run from its directory. A table (case, fault, detected after, outcome,
invariants held) goes to stdout and ``OUT/report.json`` keeps everything,
evidence included. The exit code is 1 if an invariant a case expects broke
or did not apply. A case whose faults the runtime cannot apply is skipped,
and says why.
"""

from __future__ import annotations

import fnmatch
import json
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from pathlib import Path

from bearcat.cli.arguments import Commands, UsageError
from bearcat.cli.writing import make_directory, writing
from bearcat.runtime.peers import NETWORKS
from bearcat.runtime.run_directory import fresh


def register(commands: Commands) -> None:
    p = commands.add_parser(
        "faults",
        description="Run every case of a fault-injection suite (TOML: [[case]] tables of a scenario, faults and "
        "seeds) and check each run's invariants; 'builtin' is the suite that ships with bearcat.",
    )
    p.add_argument("suite", metavar="SUITE", help="a suite file, or builtin")
    p.add_argument("--runtime", choices=("simulate", "live"), default="simulate", help="default: simulate")
    p.add_argument(
        "--network",
        choices=NETWORKS,
        default="shim",
        help="live runs: shim (default) or kernel (real packets in namespaces; needs root)",
    )
    p.add_argument("--out", type=Path, metavar="DIR", help="where the runs go (default ./runs/faults-SUITE)")
    p.add_argument(
        "--case", action="append", default=[], metavar="NAME", help="run only the cases matching NAME (a glob)"
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=1,
        metavar="N",
        help="runs at once (default 1; live runs share the processor, and a loaded one stretches detection times)",
    )
    p.set_defaults(run=run_suite)


def run_suite(args) -> int:
    from bearcat.scenarios.faults import refusal
    from bearcat.suites.suite import builtin_suite, load_suite, run_case, table

    if args.runtime == "simulate" and args.network != "shim":
        raise UsageError("--network kernel needs --runtime live: a simulated run has no packets")
    if args.network == "kernel":
        from bearcat.netem.kernel.commands import KernelError
        from bearcat.netem.kernel.network import missing

        if (why := missing()) is not None:
            raise KernelError(why)
    path = builtin_suite() if args.suite == "builtin" else Path(args.suite)
    name, cases = load_suite(path)
    if args.case:
        cases = [c for c in cases if any(fnmatch.fnmatch(c.name, pattern) for pattern in args.case)]
        if not cases:
            raise UsageError(f"no case of suite {name} matches {', '.join(args.case)}")
    if args.jobs < 1:
        raise UsageError("--jobs must be at least 1")
    out = fresh(args.out or Path("runs") / f"faults-{name}")
    make_directory(out, "run directory")
    skipped, todo = [], []
    for case in cases:
        why = refusal(case.faults, args.runtime)
        if why is not None:
            skipped.append({"case": case.name, "why": why})
            print(f"{case.name}: skipped: {why}", flush=True)
        else:
            todo += [(case, seed) for seed in case.seeds]

    def run(job):
        case, seed = job
        result = run_case(case, seed, out / case.name / f"seed-{seed}", runtime=args.runtime, network=args.network)
        print(f"{case.name} seed {seed}: {'ok' if result.passed else 'FAILED'}: {result.outcome}", flush=True)
        return result

    with writing(out, "run directory"):
        if args.runtime == "live":  # solved before any game starts, once a game
            from bearcat.cli.presolve import presolve

            for case in {case.name: case for case, _ in todo}.values():
                presolve(case.scenario, case.netem or case.scenario.netem)
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            results = list(pool.map(run, todo))
        report = {
            "suite": name,
            "runtime": args.runtime,
            "network": args.network,
            "passed": all(r.passed for r in results),
            "cases": [asdict(r) | {"passed": r.passed} for r in results],
            "skipped": skipped,
        }
        (out / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    print()
    print(table(results))
    print(
        f"\n{sum(r.passed for r in results)} of {len(results)} runs held every invariant they expect; "
        f"{len(skipped)} case(s) skipped; report: {out / 'report.json'}"
    )
    return 0 if report["passed"] else 1
