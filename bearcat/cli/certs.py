"""``bearcat certs``: the certificates a guarded game's peers present.

``bearcat certs init DIR --scenario S`` makes an authority in DIR (unless
one is there) and issues a certificate for every peer of the scenario that
lacks one; run it again for another scenario, with ``--phone`` for an
agent a person plays, or with ``--host`` for an address peers on other
machines reach the router at (its certificate, ``launcher.pem``, is issued
again naming it). ``bearcat certs list DIR`` says who holds what, and at
which names and addresses the router's certificate serves.
"""

from __future__ import annotations

from pathlib import Path

from bearcat.cli import arguments
from bearcat.cli.arguments import Commands


def register(commands: Commands) -> None:
    certs = commands.add_parser(
        "certs",
        description="Make and list the certificates of a game's peers: an authority, and one certificate per "
        "peer whose common name is the peer's id (bearcat run --certs DIR --secure).",
    )
    actions = certs.add_subparsers(dest="action", metavar="ACTION", required=True)
    init = actions.add_parser(
        "init",
        help="make an authority in DIR (if none is there) and a certificate for every peer of a scenario",
        description="Make an authority in DIR (if none is there) and issue a certificate and key for every "
        "peer of SCENARIO that has none: the ground station gs, the launcher, each agent (a walker, or a phone "
        "with --phone) and each UAV. Keys are readable by their owner only; copy to each machine only its own.",
    )
    init.add_argument("directory", metavar="DIR", type=Path)
    init.add_argument("--scenario", required=True, metavar="SCENARIO", help="a built-in scenario or a TOML file")
    init.add_argument(
        "--phone",
        action="append",
        default=[],
        metavar="AGENT",
        help="an agent a person plays on a real phone (repeatable): its certificate publishes fixes, not truth",
    )
    init.add_argument(
        "--host",
        action="append",
        default=[],
        type=arguments.host,
        metavar="ADDRESS",
        help="an address (or DNS name) peers on other machines reach the router at, e.g. the field laptop's "
        "192.168.1.10 (repeatable): the router's certificate (launcher.pem) names it, issued again if it lacks it",
    )
    init.set_defaults(run=run_init)
    listing = actions.add_parser(
        "list", help="who holds a valid certificate in DIR, in which role, and where the router's names it"
    )
    listing.add_argument("directory", metavar="DIR", type=Path)
    listing.set_defaults(run=run_list)


def run_init(args) -> int:
    from bearcat.bus.identity import hosts_named
    from bearcat.runtime.credentials import add_to
    from bearcat.scenarios.faults import LAUNCHER
    from bearcat.scenarios.schema import load_scenario

    scenario = load_scenario(args.scenario)
    issued = add_to(args.directory, scenario, phones=tuple(args.phone), hosts=tuple(args.host))
    for name, role in issued.items():
        print(f"{args.directory / name}.pem  {role} {name}")
    if not issued:
        print(f"{args.directory}: every peer of {scenario.name} holds a certificate already")
    if args.host:
        print(f"the router's certificate names {', '.join(hosts_named(args.directory, LAUNCHER))}")
    return 0


def run_list(args) -> int:
    from bearcat.bus.identity import hosts_named, members_of

    for name, member in sorted(members_of(args.directory).items()):
        keyed = "key here" if (args.directory / f"{name}.key").exists() else "no key here"
        reached = f"  (router at {', '.join(hosts_named(args.directory, name))})" if member.role == "launcher" else ""
        print(f"{name:<20} {member.role:<15} {keyed}{reached}")
    return 0
