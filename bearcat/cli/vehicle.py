"""``bearcat vehicle``: the MAVLink vehicle emulator, one PX4 quadrotor per process."""

from __future__ import annotations

from bearcat.cli.arguments import Commands, UsageError, seed


def register(commands: Commands) -> None:
    vehicle = commands.add_parser(
        "vehicle",
        description="Emulate one PX4 quadrotor on MAVLink over UDP: a point mass with acceleration, speed and "
        "climb limits, optional wind and a draining battery. By PX4 SITL's convention vehicle i sends to "
        "127.0.0.1:14540+i with system id i+1; fly it with MAVSDK on udpin://0.0.0.0:14540+i.",
    )
    vehicle.add_argument(
        "--connect",
        default="udpout:127.0.0.1:14540",
        metavar="URL",
        help="pymavlink URL to talk on (default udpout:127.0.0.1:14540)",
    )
    vehicle.add_argument("--sysid", type=int, default=1, metavar="N", help="MAVLink system id, 1-254 (default 1)")
    vehicle.add_argument(
        "--home",
        required=True,
        metavar="LAT,LON,ALT",
        help="home: latitude and longitude in degrees and altitude AMSL in metres",
    )
    vehicle.add_argument(
        "--max-speed", type=float, default=8.0, metavar="M/S", help="horizontal speed limit (default 8)"
    )
    vehicle.add_argument("--wind", default="0,0", metavar="E,N", help="mean wind, m/s east and north (default 0,0)")
    vehicle.add_argument("--gust", type=float, default=0.0, metavar="M/S", help="gust standard deviation (default 0)")
    vehicle.add_argument(
        "--endurance", type=float, default=1200.0, metavar="S", help="hover time on a full battery (default 1200 s)"
    )
    vehicle.add_argument("--seed", type=seed, default=0, metavar="S", help="seed of the gusts (default 0)")
    vehicle.set_defaults(run=run_vehicle)


def run_vehicle(args) -> int:
    from bearcat.agents.uav.airframe import Airframe
    from bearcat.agents.uav.emulator import serve

    if not 1 <= args.sysid <= 254:
        raise UsageError(f"--sysid {args.sysid} is not a MAVLink system id (1-254)")
    home = _numbers(args.home, 3, "--home")
    wind = _numbers(args.wind, 2, "--wind")
    if not (-90 <= home[0] <= 90 and -180 <= home[1] <= 180):
        raise UsageError(f"--home {args.home} is not a latitude and longitude in degrees")
    airframe = Airframe(max_speed=args.max_speed, wind=(wind[0], wind[1]), gust=args.gust, endurance=args.endurance)
    counts = serve(args.connect, args.sysid, (home[0], home[1], home[2]), airframe=airframe, seed=args.seed)
    print(f"vehicle {args.sysid}: {counts.received} messages in, {counts.sent} out, {counts.bad} undecodable")
    return 0


def _numbers(text: str, count: int, option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != count:
        raise UsageError(f"{option} {text!r} must be {count} comma-separated numbers")
    return values
