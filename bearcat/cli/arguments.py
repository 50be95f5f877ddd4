"""What several commands share: parsers for the values they take (``X,Y``,
``X,Y,R``, seeds, counts), the options of a batch of trials, and the
``Commands`` the command modules register into.

The parsers raise ``argparse.ArgumentTypeError`` so argparse reports the
culprit option with exit code 2, like any other bad argument.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path


class UsageError(Exception):
    """Arguments that parse one by one but do not fit together; the message says how."""


def numbers(text: str, counts: tuple[int, ...], what: str) -> tuple[float, ...]:
    """Split ``text`` on commas into finite floats; the count must be one of ``counts``."""
    parts = text.split(",")
    if len(parts) not in counts:
        expected = " or ".join(str(c) for c in counts)
        raise argparse.ArgumentTypeError(f"{what} {text!r} needs {expected} comma-separated numbers")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} {text!r} is not a list of numbers") from None
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{what} {text!r} has a value that is not a finite number")
    return values


def point(text: str) -> tuple[float, float]:
    """``X,Y`` in map metres."""
    return numbers(text, (2,), "point")  # type: ignore[return-value]


def positive(text: str) -> float:
    """A finite number above zero (speeds, radii, spacings)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number above zero")
    return value


def non_negative(text: str) -> float:
    """A finite number at or above zero (radii that may vanish)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number at or above zero")
    return value


#: The largest seed: numpy's classic 32-bit seed range, which every random
#: stream of a run is spawned from and a peer's command line carries.
MAX_SEED = 2**32 - 1


def count(text: str) -> int:
    """A whole number of at least one (trials, games)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is below 1")
    return value


def seed(text: str) -> int:
    """A whole number from 0 to ``MAX_SEED``."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"seed {text!r} is not a whole number") from None
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"seed {text!r} is not between 0 and {MAX_SEED}")
    return value


def host(text: str) -> str:
    """An address or DNS name at which another machine reaches this one (not every interface)."""
    from bearcat.bus.endpoints import WILDCARDS, check_host
    from bearcat.bus.errors import BusError

    try:
        checked = check_host(text)
    except BusError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if checked in WILDCARDS:
        raise argparse.ArgumentTypeError(
            f"{text} means every interface, which no peer connects to: name an address of this machine, "
            "e.g. 192.168.1.10"
        )
    return checked


def endpoint(text: str):
    """A Zenoh endpoint ``PROTOCOL/HOST:PORT`` (``bus.endpoints.Endpoint``)."""
    from bearcat.bus.endpoints import parse_endpoint
    from bearcat.bus.errors import BusError

    try:
        return parse_endpoint(text)
    except BusError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def check_seeds(first: int, count: int) -> None:
    """Seeds ``first`` to ``first + count - 1`` must all be seeds."""
    if first + count - 1 > MAX_SEED:
        raise UsageError(f"--seed {first} with {count} trials runs past the largest seed, {MAX_SEED}")


def change(text: str) -> tuple[str, object]:
    """``KEY=VALUE`` as a variant's change: VALUE read as a TOML value
    (``3.0``, ``true``, ``"fake-out"``, ``{ standoff = 3.0 }``), or as the
    plain text it is when it is none. A plug-in named by a file relative to
    this folder is named by its absolute path, which a worker in another
    folder finds too."""
    import tomllib

    key, equals, value = text.partition("=")
    if not equals or not key.strip():
        raise argparse.ArgumentTypeError(f"{text!r} is not KEY=VALUE")
    try:
        read: object = tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError:
        read = value.strip()
    return key.strip(), plugin(read) if isinstance(read, str) else read


def plugin(name: str) -> str:
    """A plug-in's name as given; one named by a file relative to this
    folder (``file.py:attribute``) by the file's absolute path, which a
    worker in another folder finds too."""
    where, _, attribute = name.rpartition(":")
    return f"{Path(where).resolve()}:{attribute}" if where.endswith(".py") else name


def add_struct_options(parser: argparse.ArgumentParser, struct: type, *, names=None, flags=None, types=None) -> None:
    """A flag per field of the msgspec ``struct`` (those in ``names``; by
    default every field but the first), so a setting a struct carries across
    a process boundary is spelled once, in the struct: the flag is the
    field's name with dashes (or ``flags[name]``), its help the field's
    description and its placeholder the ``metavar`` of its ``extra``. A bool
    is a switch, a tuple a repeatable flag, a Literal its choices, an int
    read as one (or each by ``types[name]``). A flag not given is None, so
    the struct's own default stands."""
    from msgspec import inspect as mi

    info = mi.type_info(struct)
    assert isinstance(info, mi.StructType), f"{struct} is not a msgspec Struct"
    for field in info.fields[1:] if names is None else [f for f in info.fields if f.name in names]:
        node, description = field.type, ""
        extra: dict = {}
        while isinstance(node, mi.Metadata | mi.UnionType):
            if isinstance(node, mi.Metadata):
                description = (node.extra_json_schema or {}).get("description", description)
                extra = {**extra, **(node.extra or {})}
                node = node.type
            else:
                node = next(t for t in node.types if not isinstance(t, mi.NoneType))
        options: dict = {"dest": field.name, "help": description, "default": None}
        if isinstance(node, mi.BoolType):
            options["action"] = "store_true"
        elif isinstance(node, mi.VarTupleType | mi.ListType):
            options["action"] = "append"
        elif isinstance(node, mi.LiteralType):
            options["choices"] = node.values
        elif isinstance(node, mi.IntType):
            options["type"] = int
        if types and field.name in types:
            options["type"] = types[field.name]
        if "metavar" in extra:
            options["metavar"] = extra["metavar"]
        parser.add_argument((flags or {}).get(field.name, "--" + field.name.replace("_", "-")), **options)


def add_batch_options(parser: argparse.ArgumentParser, what: str) -> None:
    """Where a batch runs its ``what``: ``--workers N`` local processes or,
    instead, ``--cluster ADDRESS``, a Dask cluster's scheduler. One spelling
    for every command that runs a batch (``studies.batch``)."""
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=count, metavar="N", help="local worker processes (default: one per core)")
    where.add_argument(
        "--cluster",
        metavar="tcp://HOST:PORT",
        help=f"run the {what} on the Dask cluster whose scheduler listens there, instead of on this machine "
        "(pip install 'bearcat[cluster]' on every machine)",
    )


def add_device_option(parser) -> None:
    """``--device``, where a level-set solve runs (``solvers.levelset.devices``), for
    every command that may solve one."""
    from bearcat.solvers.levelset.devices import DEVICES

    parser.add_argument(
        "--device",
        choices=DEVICES,
        default="auto",
        help="where sets are solved: cpu; cuda, a CUDA GPU (pip install 'bearcat[cuda]'); auto (default), a GPU "
        "when numba-cuda finds one, else the CPU. The sets are the same, and cached alike",
    )


class Commands:
    """The sub-commands the command modules register into: ``add_parser`` as
    argparse's, and ``games(command)`` for the GAME choices of a command
    (``solve``, ``play``) that several modules add games to, made by
    whichever asks first, so no command module imports another."""

    def __init__(self, subparsers: argparse._SubParsersAction) -> None:
        self._subparsers = subparsers
        self._games: dict[str, argparse._SubParsersAction] = {}

    def add_parser(self, name: str, **options) -> argparse.ArgumentParser:
        return self._subparsers.add_parser(name, **options)

    def games(self, command: str) -> argparse._SubParsersAction:
        if command not in self._games:
            parser = self.add_parser(command)
            self._games[command] = parser.add_subparsers(dest="game", metavar="GAME", required=True)
        return self._games[command]
