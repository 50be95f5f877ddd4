"""``bearcat check``: which invariants a run directory shows held.

One line per invariant (held, BROKEN, or n/a with why not), with its
evidence; ``--json`` gives the same as a list of objects. The exit code is
1 if any invariant broke, so a script can gate on it.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from bearcat.cli.arguments import Commands
from bearcat.cli.output import Output

MARKS = {True: "held", False: "BROKEN", None: "n/a"}


def register(commands: Commands) -> None:
    check = commands.add_parser(
        "check",
        description="Read a run directory (bearcat run --out, bearcat simulate --out DIR/seed-S) and say which "
        "invariants held: logs complete, reliable messages delivered, the verdict agrees with the truth, "
        "faults detected in time, UAV failsafes applied, nothing left running.",
    )
    check.add_argument("run_dir", metavar="RUN", type=Path, help="a run directory")
    check.add_argument("--json", action="store_true", help="print the findings as JSON only")
    check.set_defaults(run=run_check)


def run_check(args) -> int:
    from bearcat.suites.checker import check_run

    findings = check_run(args.run_dir)
    out = Output(args.json)
    width = max(len(f.name) for f in findings)
    for f in findings:
        out.say(f"{MARKS[f.held]:>6}  {f.name:<{width}} {f.evidence}")
    out.json([asdict(f) for f in findings])
    return 1 if any(f.held is False for f in findings) else 0
