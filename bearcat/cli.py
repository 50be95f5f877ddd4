"""Entry point of the ``bearcat`` command.

Each subcommand module registers its parser and a ``run(args)`` callable.
Errors a user can cause surface here as one sentence and exit code 2; anything
else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import logging
import sys

from bearcat import __version__
from bearcat.arguments import UsageError
from bearcat.bus.errors import BusError
from bearcat.commands import ctf as ctf_command
from bearcat.commands import experiment as experiment_command
from bearcat.commands import live as live_command
from bearcat.commands import maps as maps_command
from bearcat.commands import simulate as simulate_command
from bearcat.commands import solve as solve_command
from bearcat.commands import study as study_command
from bearcat.commands import vehicle as vehicle_command
from bearcat.maps.errors import MapError
from bearcat.netem.profiles import ProfileError
from bearcat.scenarios.schema import ScenarioError
from bearcat.solvers.errors import InputError

USER_ERRORS = (
    UsageError,
    MapError,
    InputError,
    ScenarioError,
    ProfileError,
    BusError,
    FileNotFoundError,
    IsADirectoryError,
    PermissionError,
    TimeoutError,
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="bearcat",
        description="Field simulator and reachability solvers for adversarial games.",
    )
    parser.add_argument("--version", action="version", version=f"bearcat {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="log more (repeat for debug)")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in (
        maps_command,
        solve_command,
        ctf_command,
        experiment_command,
        simulate_command,
        live_command,
        study_command,
        vehicle_command,
    ):
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=(logging.WARNING, logging.INFO, logging.DEBUG)[min(args.verbose, 2)],
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.run(args) or 0)
    except USER_ERRORS as exc:
        print(f"bearcat: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("bearcat: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
