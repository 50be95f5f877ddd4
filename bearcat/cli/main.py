"""Entry point of the ``bearcat`` command.

Each subcommand module registers its parser and a ``run(args)`` callable.
Errors a user can cause surface here as one sentence and exit code 2; anything
else is a bug and keeps its traceback.

The command line is parsed twice. The first pass knows only the command
names of ``COMMANDS``, so ``bearcat --help``, ``bearcat --version`` and a
mistyped command answer without importing a solver, numpy or Zenoh; the
second builds the full parser of the one module the chosen command lives in.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from bearcat import __version__
from bearcat.cli import arguments
from bearcat.cli.arguments import UsageError
from bearcat.cli.writing import WriteError

#: Each command, the modules of ``bearcat.cli`` that register and run it
#: (several, for a command whose games they share), and its line in
#: ``bearcat --help``, in the order that help lists them.
COMMANDS = {
    "maps": (("maps",), "list and show maps"),
    "solve": (("solve", "ctf", "maneuver"), "run a solver once on a map"),
    "query": (("ctf",), "ask a solved game about a state"),
    "play": (("ctf", "maneuver"), "play a solved game or a designed maneuver out in closed loop"),
    "experiment": (("experiment",), "run a batch of trials"),
    "simulate": (("simulate",), "play a scenario in virtual time, every peer in this process"),
    "run": (("live",), "play a scenario live: every peer its own process over Zenoh"),
    "view": (("live",), "replay a run's Rerun recording"),
    "check": (("check",), "say which invariants a run directory shows held"),
    "plugins": (("plugins",), "list the plug-ins scenarios may name, or check what one names"),
    "faults": (("faults",), "run a fault-injection suite and check every run"),
    "peer": (("live",), "start one peer by hand (a person at a keyboard, or against real hardware)"),
    "phone": (("live",), "let a person play from a real phone's browser"),
    "certs": (("certs",), "make the certificates a guarded game's peers present"),
    "calibrate": (("calibrate",), "measure, on simulated games, the margin calibrated guidance adds to its value"),
    "study": (
        ("study",),
        "the fake-out, go/no-go and UAV search studies of thesis 3.5 and 6.2.4, as batches of simulated games",
    ),
    "vehicle": (
        ("vehicle",),
        "run a MAVLink vehicle emulator that MAVSDK and ground stations take for a PX4 quadrotor",
    ),
}


def user_errors() -> tuple[type[BaseException], ...]:
    """The errors a user can cause. ``main`` looks them up only once an
    exception reaches it: the classes live beside the code that raises them,
    whose imports ``bearcat --help`` should not pay for. Of the OS's errors
    only those that can only mean a path the user gave, or a helper program
    (the Rerun viewer) that cannot run here, are; a run or cache directory
    that refuses a write arrives as ``WriteError``."""
    from bearcat.agents.registry import PluginError
    from bearcat.bus.errors import BusError
    from bearcat.figures.screenshot import ScreenshotError
    from bearcat.maps.errors import MapError
    from bearcat.netem.kernel.commands import KernelError
    from bearcat.netem.profiles import ProfileError
    from bearcat.runtime.resume import ResumeError
    from bearcat.scenarios.faults import FaultError
    from bearcat.scenarios.schema import ScenarioError
    from bearcat.solvers.errors import InputError
    from bearcat.studies.batch import BatchInterrupted

    return (
        UsageError,
        ResumeError,
        ScreenshotError,
        WriteError,
        MapError,
        InputError,
        ScenarioError,
        FaultError,
        ProfileError,
        KernelError,
        BusError,
        BatchInterrupted,
        PluginError,
        FileNotFoundError,
        IsADirectoryError,
        PermissionError,
        TimeoutError,
        ChildProcessError,
    )


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of ``command`` (and of the other commands its module
    registers), or with no command one that only tells the commands apart."""
    parser = argparse.ArgumentParser(
        prog="bearcat",
        description="Field simulator and reachability solvers for adversarial games.",
    )
    parser.add_argument("--version", action="version", version=f"bearcat {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="log more (repeat for debug)")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    if command is None:
        for name, (_, summary) in COMMANDS.items():
            subparsers.add_parser(name, help=summary, add_help=False)
    else:
        commands = arguments.Commands(subparsers)
        for module in COMMANDS[command][0]:
            importlib.import_module(f"bearcat.cli.{module}").register(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    chosen, _ = build_parser().parse_known_args(argv)
    args = build_parser(chosen.command).parse_args(argv)
    logging.basicConfig(
        level=(logging.WARNING, logging.INFO, logging.DEBUG)[min(args.verbose, 2)],
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.run(args) or 0)
    except user_errors() as exc:  # evaluated only when an exception arrives
        print(f"bearcat: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("bearcat: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
