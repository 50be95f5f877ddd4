"""``bearcat run`` and ``bearcat peer``: live runs, every peer its own process over Zenoh."""

from __future__ import annotations

import argparse
from contextlib import nullcontext
from pathlib import Path

from bearcat.cli import arguments
from bearcat.cli.arguments import Commands
from bearcat.cli.presolve import await_behind, presolve
from bearcat.cli.writing import make_directory, writing
from bearcat.runtime.peer_spec import ROLES, PeerSpec
from bearcat.runtime.peers import NETWORKS
from bearcat.runtime.run_directory import fresh
from bearcat.runtime.solve_ahead import SolveBehind, compile_kernels_behind
from bearcat.scenarios.faults import load_faults
from bearcat.scenarios.schema import TRANSPORTS, load_scenario


def register(commands: Commands) -> None:
    run = commands.add_parser(
        "run",
        description="Start the ground station and one walker peer per agent as processes on this host, wait "
        "for all of them (and for those started by hand, here or on other machines), start the game, and stop "
        "every peer it started when it ends (or on Ctrl-C, or when a peer dies).",
    )
    run.add_argument("scenario", nargs="?", metavar="SCENARIO", help="a built-in scenario name or a scenario TOML file")
    run.add_argument(
        "--resume",
        type=Path,
        metavar="RUN",
        help="take up again the run in RUN, whose launcher died: the same settings, router port and certificates; "
        "the ground station resumes from its log, the walkers where they stood, and the logs carry on",
    )
    run.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="run directory (default ./runs/SCENARIO-SEED; DIR-1, DIR-2, ... if it holds something already)",
    )
    run.add_argument("--seed", type=arguments.seed, metavar="S", help="seed (default: the scenario's)")
    run.add_argument("--netem", metavar="PROFILE", help="network profile instead of the scenario's")
    run.add_argument(
        "--network",
        choices=NETWORKS,
        default="shim",
        help="shim (default): each peer impairs the messages it receives; kernel: every peer in a network "
        "namespace of its own, its packets impaired by the kernel (needs root)",
    )
    run.add_argument(
        "--transport",
        choices=TRANSPORTS,
        help="how fixes and guidance travel: tcp (retransmitted, late) or udp (lost); default: the scenario's",
    )
    run.add_argument(
        "--faults",
        type=Path,
        metavar="FILE",
        help="a fault plan ([[fault]] tables) to apply instead of the scenario's own",
    )
    run.add_argument(
        "--certs",
        type=Path,
        metavar="DIR",
        help="certificates of every peer (bearcat certs init); default: a new authority for this run alone",
    )
    run.add_argument(
        "--secure",
        action="store_true",
        help="a guarded bus: the router takes only tls/ links with a certificate from the run's authority, and "
        "lets each peer publish and read only what its role may (default-deny access control)",
    )
    run.add_argument(
        "--phone",
        action="append",
        default=[],
        metavar="AGENT",
        help="a person plays AGENT from a real phone (repeatable): its page is served instead of a walker, the "
        "link printed, and the game waits for the phone's first fix; the referee judges on fixes",
    )
    run.add_argument(
        "--joins",
        action="append",
        default=[],
        metavar="AGENT",
        help="AGENT's peer is started by hand, not by the launcher (repeatable): a walker or UAV in another terminal "
        "or on another machine (with --listen) or, with --phone AGENT, the page bridge (bearcat phone, e.g. with a "
        "certificate of your own); the launcher prints the command and waits for it",
    )
    run.add_argument(
        "--listen",
        action="append",
        default=[],
        type=arguments.endpoint,
        metavar="ENDPOINT",
        help="the router also takes peers from other machines here (repeatable), e.g. tls/0.0.0.0:7447 or "
        "tls/192.168.1.10:7447 with --secure, tcp/... without; the launcher prints where they join and the "
        "command each of --joins runs",
    )
    run.add_argument(
        "--page",
        type=_host_and_port,
        default=("0.0.0.0", 8443),
        metavar="HOST:PORT",
        help="where the phones' pages are served (default 0.0.0.0:8443; the next phone on the next port)",
    )
    run.add_argument(
        "--wait-for-sets",
        action="store_true",
        help="solve the scenario's sets before the game starts; by default a capture-the-flag game whose sets "
        "are not cached starts at once on provisional ones (rules.provisional_grid) while they solve behind it",
    )
    run.add_argument("--viewer", action="store_true", help="open the recording in the Rerun viewer at the end")
    run.add_argument("--headless", action="store_true", help="no viewer (the default)")
    run.set_defaults(run=run_live)

    view = commands.add_parser(
        "view",
        description="Open RUN/recording.rrd in the Rerun viewer (made from RUN/events.jsonl if missing), "
        "or save a picture of it at a game time.",
    )
    view.add_argument(
        "run_dir", metavar="RUN", type=Path, help="a run directory (bearcat run --out, bearcat simulate --out)"
    )
    view.add_argument(
        "--screenshot",
        type=Path,
        metavar="PNG",
        help="render headless to this PNG instead of opening a window (needs a Vulkan driver such as mesa's)",
    )
    view.add_argument(
        "--at",
        type=arguments.non_negative,
        metavar="SECONDS",
        help="with --screenshot: the game time to show, in seconds from the start (default: the end)",
    )
    view.set_defaults(run=run_view)

    peer = commands.add_parser(
        "peer",
        description="Start one peer of a scenario: the ground station (referee, guidance and UAV tasking), one "
        "walker, or one UAV flying a MAVLink vehicle (the emulator of bearcat vehicle, PX4 SITL or a real PX4).",
    )
    peer.add_argument("role", nargs="?", choices=ROLES)
    peer.add_argument(
        "--spec",
        type=Path,
        metavar="FILE",
        help="every setting from this file (RUN/peers/NAME.spec.json, as bearcat run writes it) instead of "
        "ROLE and the options below",
    )
    arguments.add_struct_options(peer, PeerSpec, types={"seed": arguments.seed, "page": _address})
    peer.set_defaults(run=run_peer)

    phone = commands.add_parser(
        "phone",
        description="Let a person play from a real phone: serve a page to the phone's browser over HTTPS and "
        "bridge it to the game (its GPS and compass as fixes, the ground station's guidance on its screen). "
        "Prints the link and a QR code to open on the phone.",
    )
    phone.add_argument("--connect", action="append", required=True, metavar="ENDPOINT", help="the game's router")
    phone.add_argument("--game", required=True, metavar="GAME", help="the game (its ground station serves the map)")
    phone.add_argument("--id", required=True, metavar="AGENT", help="the agent this person plays")
    arguments.add_struct_options(
        phone,
        PeerSpec,
        names=("certs", "secure", "out", "hand_in", "page", "cert", "key", "token_file"),
        flags={"page": "--listen"},
        types={"page": _address},
    )
    phone.set_defaults(run=run_phone)


def run_live(args) -> int:
    from bearcat.runtime.launch import launch, preflight
    from bearcat.scenarios.cast import awaited_sets, unsolved

    if args.resume is not None:
        return _resume(args)
    if args.scenario is None:
        raise arguments.UsageError("bearcat run needs a SCENARIO, or --resume RUN to take up a run whose launcher died")
    if args.network == "kernel":
        from bearcat.netem.kernel.commands import KernelError
        from bearcat.netem.kernel.network import missing

        if (why := missing()) is not None:
            raise KernelError(why)
    scenario = load_scenario(args.scenario)
    plan = scenario.faults if args.faults is None else load_faults(args.faults, scenario)
    seed = scenario.seed if args.seed is None else args.seed
    netem = args.netem or scenario.netem
    preflight(
        scenario,
        plan,
        transport=args.transport or scenario.transport,
        secure=args.secure,
        certs=args.certs,
        phones=tuple(args.phone),
        joins=tuple(args.joins),
        listen=tuple(args.listen),
        page=args.page,
    )
    out = fresh(args.out or Path("runs") / f"{scenario.name}-{seed}")
    make_directory(out, "run directory")

    def say(text: str) -> None:
        print(text, flush=True)

    awaited = None if args.wait_for_sets else awaited_sets(scenario)
    behind = None
    compiling = compile_kernels_behind() if unsolved(scenario) else None  # numba's cache may be empty too
    try:
        presolve(scenario, netem, provisional=awaited is not None)
        if awaited is not None:
            behind = SolveBehind(awaited)
            say(
                f"{scenario.name}: guidance starts on the {awaited.provisional}-point sets and takes up the "
                f"{awaited.game.grid_points}-point sets once they are solved behind the game"
            )
        with writing(out, "run directory"):
            outcome = launch(
                scenario,
                _reference(args.scenario),
                out,
                seed=seed,
                netem=netem,
                transport=args.transport,
                network=args.network,
                say=say,
                faults=plan,
                certs=args.certs,
                secure=args.secure,
                phones=tuple(args.phone),
                joins=tuple(args.joins),
                page=args.page,
                provisional=awaited is not None,
                listen=tuple(args.listen),
            )
        who = f"{outcome.winner} wins" if outcome.winner else "no winner"
        say(f"{scenario.name}: {who} at {outcome.elapsed:.1f} s: {outcome.reason}")
        say(f"run directory: {out} (events.jsonl, outcome.json, recording.rrd, peers/); replay: bearcat view {out}")
        if behind is not None and outcome.reason != "interrupted":
            await_behind(behind, say)
    finally:
        if behind is not None:
            behind.stop()
        if compiling is not None:
            compiling.terminate()
            compiling.join()
    if args.viewer:
        _open_viewer(out / "recording.rrd")
    return 0 if outcome.ended else 1


def _resume(args) -> int:
    """``bearcat run --resume RUN``: the run's own settings, which no flag may change."""
    from bearcat.bus.endpoints import parse_endpoint
    from bearcat.runtime.launch import launch
    from bearcat.runtime.resume import takes_up
    from bearcat.runtime.run_directory import SCENARIO

    given = [f"--{name}" for name in ("seed", "netem", "transport", "faults", "certs", "out") if getattr(args, name)]
    given += [f"--{name}" for name in ("secure", "phone", "joins", "listen") if getattr(args, name)]
    if args.scenario is not None or given:
        what = "a SCENARIO" if args.scenario is not None else given[0]
        raise arguments.UsageError(f"--resume RUN takes the run's own settings: {what} cannot be given with it")
    out = args.resume
    launched = takes_up(out)
    scenario = load_scenario(out / SCENARIO)
    presolve(scenario, launched.netem, provisional=launched.provisional)
    with writing(out, "run directory"):
        outcome = launch(
            scenario,
            launched.scenario_ref,
            out,
            seed=launched.seed,
            netem=launched.netem,
            transport=launched.transport,
            network=launched.network,
            say=lambda text: print(text, flush=True),
            faults=(),
            certs=None if launched.certs is None else Path(launched.certs),
            secure=launched.secure,
            phones=launched.phones,
            joins=launched.joins,
            page=launched.page,
            provisional=launched.provisional,
            listen=tuple(parse_endpoint(e) for e in launched.listen),
            taken_up=launched,
        )
    who = f"{outcome.winner} wins" if outcome.winner else "no winner"
    print(f"{scenario.name}: {who} at {outcome.elapsed:.1f} s: {outcome.reason}", flush=True)
    print(f"run directory: {out}; replay: bearcat view {out}", flush=True)
    return 0 if outcome.ended else 1


def run_view(args) -> int:
    from bearcat.agents.ground_station.rerun_recording import write_recording
    from bearcat.maps import read_geojson

    rrd = args.run_dir / "recording.rrd"
    if not rrd.exists():
        events, map_file = args.run_dir / "events.jsonl", args.run_dir / "map.geojson"
        if not (events.exists() and map_file.exists()):
            raise FileNotFoundError(
                f"{args.run_dir} is not a run directory: it has no recording.rrd nor events.jsonl and map.geojson"
            )
        write_recording(events, read_geojson(map_file), rrd, name=args.run_dir.name)
    if args.screenshot is not None:
        from bearcat.figures.screenshot import screenshot

        shown = screenshot(rrd, args.screenshot, at=args.at)
        print(f"{args.screenshot}: {args.run_dir} at {shown:.1f} s of game time")
        return 0
    if args.at is not None:
        raise arguments.UsageError("--at needs --screenshot: the viewer's time line sets the time of an open window")
    return _open_viewer(rrd)


def _open_viewer(rrd: Path, *extra: str) -> int:
    """The Rerun viewer on ``rrd``; its server (which it starts with every window) on the loopback only."""
    import shutil
    import subprocess

    from bearcat.figures.screenshot import LOOPBACK

    viewer = shutil.which("rerun")
    if viewer is None:
        raise FileNotFoundError("the Rerun viewer is not installed: pip install rerun-sdk")
    return subprocess.call([viewer, str(rrd), "--bind", LOOPBACK, *extra])


def run_peer(args, page=None) -> int:
    from bearcat.runtime.peer_spec import read_spec, spec_of

    if args.spec is not None:
        if args.role is not None:
            raise arguments.UsageError("--spec FILE holds the peer's role and every setting: give no ROLE with it")
        spec = read_spec(args.spec)
    elif args.role is None or args.scenario is None:
        raise arguments.UsageError("bearcat peer needs a ROLE and --scenario SCENARIO, or --spec FILE")
    else:
        spec = spec_of(vars(args))
    return _run_spec(spec, page)


def _run_spec(spec, page=None) -> int:
    from bearcat.runtime.live import fetch_scenario, start_peer

    certs = None if spec.certs is None else Path(spec.certs)
    if spec.scenario.startswith("zenoh:"):
        game = spec.scenario[len("zenoh:") :]
        scenario = fetch_scenario(game, list(spec.connect), certs=certs, name=spec.name, secure=spec.secure)
    else:
        scenario = load_scenario(spec.scenario)
    if spec.role == "ground-station":
        presolve(scenario, spec.netem or scenario.netem, provisional=spec.provisional)
    with nullcontext() if spec.out is None else writing(Path(spec.out), "run directory"):
        reason = start_peer(spec, scenario, say=lambda text: print(text, flush=True), page=page)
    print(f"peer {spec.name}: {reason}", flush=True)
    return 0


def run_phone(args) -> int:
    """``bearcat phone``: ``bearcat peer phone`` with the scenario fetched from the game's ground station."""
    from bearcat.agents.human.browser_bridge import page_server
    from bearcat.runtime.peer_spec import PeerSpec

    spec = PeerSpec(
        role="phone",
        scenario=f"zenoh:{args.game}",
        id=args.id,
        connect=tuple(args.connect),
        mode="client",
        out=args.out,
        hand_in=bool(args.hand_in),
        certs=args.certs,
        secure=bool(args.secure),
    )
    server = page_server(args.page, args.cert, args.key, args.token_file)  # one token, the link's and the page's
    print(f"open {server.url()} on the phone of {args.id}\n{server.qr()}", flush=True)
    return _run_spec(spec, server)


def _host_and_port(text: str) -> tuple[str, int]:
    from bearcat.agents.human.browser_bridge import page_address
    from bearcat.bus.errors import BusError

    try:
        return page_address(text)
    except BusError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _address(text: str) -> str:
    """``HOST:PORT``, checked, as the peer's spec keeps it."""
    _host_and_port(text)
    return text


def _reference(text: str) -> str:
    """How child processes find the scenario: built-in names as they are, files by absolute path."""
    path = Path(text)
    return str(path.resolve()) if path.exists() else text
