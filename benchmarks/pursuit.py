"""The pursuit benchmarks of thesis chapter 5 in one run:

    python benchmarks/pursuit.py            # control steps, analytic and fast-marching
    python benchmarks/pursuit.py --table    # and the whole 9-cell, 500-trial Table 5.1, timed

The control steps are timed by ``benchmarks/pursuit_convex.py`` (the
analytic strategy of 5.2.1 against the same step on shapely) and
``benchmarks/pursuit_fmm.py`` (the fast-marching strategy of 5.2.2 on a
101 x 101 grid), each runnable alone. ``--table`` runs
``bearcat experiment pursuit`` as a user would, into a fresh directory, and
reports its wall time: the target is under 30 minutes on two cores.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def run(script: str, *words: str) -> None:
    print(f"== {script} {' '.join(words)}".rstrip(), flush=True)
    subprocess.run([sys.executable, os.path.join(HERE, script), *words], check=True)
    print(flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--table", action="store_true", help="also time the full Table 5.1 run")
    parser.add_argument("--trials", type=int, default=500, help="trials per cell for --table (default 500)")
    args = parser.parse_args()
    run("pursuit_convex.py")
    run("pursuit_fmm.py")
    if args.table:
        with tempfile.TemporaryDirectory() as out:
            print(
                f"== bearcat experiment pursuit, 9 cells x {args.trials} trials, {os.cpu_count()} workers", flush=True
            )
            start = time.perf_counter()
            subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "bearcat",
                    "experiment",
                    "pursuit",
                    "--trials",
                    str(args.trials),
                    "--out",
                    os.path.join(out, "run"),
                ],
                check=True,
            )
            print(f"whole table: {(time.perf_counter() - start) / 60:.1f} min wall")


if __name__ == "__main__":
    main()
