"""What one peer process is started with, as one typed value.

The launcher writes a peer's ``PeerSpec`` to ``RUN/peers/NAME.spec.json``
and starts ``bearcat peer --spec FILE``; a person who starts a peer by hand
types the same settings as flags (``bearcat peer ROLE --scenario ...``),
which the command line reads into the same value, and the launcher prints
those flags from a spec (``flags``). ``live.start_peer(spec)`` runs it. So a
setting that crosses the process boundary is a field here, spelled once,
and its flag is its name (``--token-file`` for ``token_file``, ``--id``
for ``id``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import msgspec
from msgspec import Meta

from bearcat.bus.errors import BusError
from bearcat.scenarios.faults import GROUND

Role = Literal["ground-station", "walker", "phone", "uav"]
ROLES: tuple[str, ...] = Role.__args__  # type: ignore[attr-defined]


def _said(description: str, metavar: str | None = None) -> Meta:
    """A field's help on the command line (``bearcat peer``), and the placeholder its flag shows."""
    return Meta(description=description, extra={} if metavar is None else {"metavar": metavar})


class PeerSpec(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """One peer: ``role`` and ``id`` (the agent or UAV; the ground station's
    own name for it), the scenario and how to join, how it impairs what it
    receives, where it logs, and a role's own settings. Each field's
    description is its flag's help: ``bearcat peer``'s options are made
    from these fields (``cli.arguments.add_struct_options``), so a setting is
    spelled once."""

    role: Role
    scenario: Annotated[
        str,
        _said(
            "built-in scenario name, TOML file, or zenoh:GAME to fetch it (and its map) from the ground station",
            "SCENARIO",
        ),
    ]
    id: Annotated[str, _said("the walker's or UAV's id (ignored for the ground station)", "ID")] = GROUND
    connect: Annotated[
        tuple[str, ...], _said("Zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)", "ENDPOINT")
    ] = ()
    listen: Annotated[
        tuple[str, ...] | None,
        _said("Zenoh endpoint to listen on (default tcp/127.0.0.1:0; clients do not listen)", "ENDPOINT"),
    ] = None
    mode: Annotated[
        Literal["peer", "client"],
        _said("Zenoh mode: peer (default) or client of the router it connects to (what bearcat run uses)"),
    ] = "peer"
    seed: Annotated[int | None, _said("seed (default: the scenario's)", "S")] = None
    netem: Annotated[str | None, _said("network profile instead of the scenario's", "PROFILE")] = None
    network: Annotated[
        Literal["shim", "kernel"],
        _said(
            "shim (default): this peer impairs what it receives; kernel: the network it runs on does "
            "(GPS and compass error stay in the phone)"
        ),
    ] = "shim"
    transport: Annotated[
        Literal["tcp", "udp"] | None,
        _said("how fixes and guidance travel: tcp, or udp to the same endpoints; default: the scenario's"),
    ] = None
    out: Annotated[str | None, _said("run directory for this peer's logs", "DIR")] = None
    certs: Annotated[
        str | None,
        _said(
            "the game's certificates (RUN/certs of a bearcat run, or bearcat certs init): this peer seals what "
            "it sends with ID.key and believes only senders the authority vouches for; without it, every name",
            "DIR",
        ),
    ] = None
    secure: Annotated[
        bool, _said("join a guarded bus: a client of the router over tls/ only, presenting ID.pem from --certs")
    ] = False
    faults: Annotated[str | None, _said("the run's fault plan: apply the faults the launcher announces", "FILE")] = None
    hand_in: Annotated[
        bool,
        _said(
            "at the end, hand this peer's log in --out DIR to the launcher over the bus (a peer on another "
            "machine), keeping its own copy"
        ),
    ] = False
    resume: Annotated[
        bool, _said("take up the game where this peer's log in --out DIR left it (a peer restarted mid-game)")
    ] = False
    judge: Annotated[
        Literal["truth", "fixes"],
        _said("what the referee judges on: the simulation's truth (default), or the fixes, for real players"),
    ] = "truth"
    provisional: Annotated[
        bool,
        _said(
            "ground-station: while the scenario's sets are not in the cache, answer from provisional ones "
            "(rules.provisional_grid) and take the scenario's up once another process has solved them"
        ),
    ] = False
    vehicle: Annotated[
        str | None,
        _said(
            "uav: MAVSDK URL of the vehicle, e.g. udpin://0.0.0.0:14540 (PX4 SITL, bearcat vehicle) "
            "or serial:///dev/ttyACM0:57600 (a real PX4)",
            "URL",
        ),
    ] = None
    sysid: Annotated[int | None, _said("uav: the vehicle's MAVLink system id (default: the first autopilot)", "N")] = (
        None
    )
    emulated: Annotated[
        bool, _said("uav: the vehicle is simulated, so its telemetry is the truth the referee and recorder see")
    ] = False
    page: Annotated[
        str | None, _said("phone: where its page is served over HTTPS (default 0.0.0.0:8443)", "HOST:PORT")
    ] = None
    cert: Annotated[str | None, _said("phone: the page's HTTPS certificate (PEM)", "FILE")] = None
    key: Annotated[str | None, _said("phone: its key; without --cert/--key, one is made for the session", "FILE")] = (
        None
    )
    token_file: Annotated[
        str | None,
        _said("phone: the secret the page's link carries (default: a new one, printed in the link)", "FILE"),
    ] = None

    @property
    def name(self) -> str:
        """The peer's name on the bus: its agent's or UAV's id, the ground station's own."""
        return GROUND if self.role == "ground-station" else self.id


FIELDS = frozenset(PeerSpec.__struct_fields__)


def spec_of(settings: dict) -> PeerSpec:
    """The spec of ``settings`` (the command line's options, by field
    name; paths and lists as argparse gives them)."""
    plain = {
        name: str(value) if isinstance(value, Path) else value
        for name, value in settings.items()
        if name in FIELDS and value is not None
    }
    try:
        return msgspec.convert(plain, PeerSpec)
    except msgspec.ValidationError as exc:
        raise BusError(f"peer settings: {exc}") from None


def flags(spec: PeerSpec) -> list[str]:
    """The command line that starts ``spec``'s peer (after ``bearcat peer``),
    as a person types it: the role, then each setting that is not its default."""
    said: list[str] = [spec.role]
    for field in msgspec.structs.fields(PeerSpec)[1:]:
        value = getattr(spec, field.name)
        if not field.required and value == field.default:
            continue
        flag = "--" + field.name.replace("_", "-")
        if isinstance(value, bool):
            said.append(flag)
        elif isinstance(value, tuple):
            for item in value:
                said += [flag, item]
        else:
            said += [flag, str(value)]
    return said


def write_spec(path: Path, spec: PeerSpec) -> None:
    path.write_bytes(msgspec.json.format(msgspec.json.encode(spec)) + b"\n")


def read_spec(path: Path) -> PeerSpec:
    """The spec in ``path``; one sentence naming the file for anything else."""
    try:
        return msgspec.json.decode(path.read_bytes(), type=PeerSpec)
    except OSError as exc:
        raise BusError(f"{path}: cannot read the peer's spec: {exc.strerror or exc}") from None
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise BusError(f"{path}: not a peer spec: {exc}") from None
