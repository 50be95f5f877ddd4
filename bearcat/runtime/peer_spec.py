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
from typing import Literal

import msgspec

from bearcat.bus.errors import BusError
from bearcat.scenarios.faults import GROUND

Role = Literal["ground-station", "walker", "phone", "uav"]
ROLES: tuple[str, ...] = Role.__args__  # type: ignore[attr-defined]


class PeerSpec(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """One peer: ``role`` and ``id`` (the agent or UAV; the ground station's
    own name for it), the scenario (a built-in name, a file, or
    ``zenoh:GAME`` to fetch it from the ground station) and how to join:
    Zenoh endpoints to ``connect`` to and ``listen`` on (None: the
    default), in ``mode``; ``seed``, ``netem`` and ``transport`` None are the
    scenario's own. ``out`` is the run directory the peer logs into,
    ``certs`` the game's certificates, ``secure`` a client over ``tls/``
    only, ``faults`` the run's fault plan (a file), ``resume`` a restart
    that takes up its log. The rest is a role's own: the ground station's
    ``judge`` and ``provisional``; a UAV's ``vehicle`` URL, ``sysid`` and
    ``emulated``; a phone's ``page`` (HOST:PORT; None: 0.0.0.0:8443), its
    HTTPS ``cert`` and ``key``, and ``token_file``."""

    role: Role
    scenario: str
    id: str = GROUND
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] | None = None
    mode: Literal["peer", "client"] = "peer"
    seed: int | None = None
    netem: str | None = None
    network: Literal["shim", "kernel"] = "shim"
    transport: Literal["tcp", "udp"] | None = None
    out: str | None = None
    certs: str | None = None
    secure: bool = False
    faults: str | None = None
    resume: bool = False
    judge: Literal["truth", "fixes"] = "truth"
    provisional: bool = False
    vehicle: str | None = None
    sysid: int | None = None
    emulated: bool = False
    page: str | None = None
    cert: str | None = None
    key: str | None = None
    token_file: str | None = None

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
