"""The identities of a scenario's peers: who holds a certificate, in which role.

A live run always seals its messages. ``bearcat run`` makes a fresh
authority for the run in ``RUN/certs`` (so even a run on a shared network
with ``--secure`` off accepts game state, control and truth only from the
peers it started) unless it is given a directory ``bearcat certs init`` made,
which a field game's laptop and phones share. A run's own authority is
spent once the run is over: its private keys are deleted, and its
certificates stay as the record of who played.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bearcat.bus.errors import BusError
from bearcat.bus.identity import AUTHORITY, add_members, hosts_named, make_authority, members_of
from bearcat.scenarios.faults import GROUND, LAUNCHER
from bearcat.scenarios.schema import Scenario


def members(scenario: Scenario, phones: tuple[str, ...] = ()) -> dict[str, str]:
    """Every peer of ``scenario`` and its role; the agents in ``phones`` are real phones, the others walkers."""
    unknown = sorted(set(phones) - set(scenario.ids))
    if unknown:
        raise BusError(
            f"{scenario.source}: there is no agent {unknown[0]!r} to give a phone; the agents are "
            f"{', '.join(scenario.ids)}"
        )
    found = {GROUND: "ground-station", LAUNCHER: "launcher"}
    found |= {a: "phone" if a in phones else "walker" for a in scenario.ids}
    found |= {u.id: "uav" for u in scenario.uavs}
    return found


@contextmanager
def run_authority(
    out: Path,
    scenario: Scenario,
    given: Path | None,
    *,
    phones: tuple[str, ...] = (),
    hosts: tuple[str, ...] = (),
    again: bool = False,
) -> Iterator[Path]:
    """``with run_authority(...) as directory:`` the certificates of a run into
    ``out``: ``given`` if it covers every peer of ``scenario`` in its role (a
    sentence naming the first that it does not, otherwise), else a new
    authority in ``out/certs`` whose certificates name ``hosts`` too (where
    the router listens), spent when the run is over; a run taken up
    ``again`` keeps the one its dead launcher made, which it did not spend."""
    if given is not None:
        yield covering(given, scenario, phones)
        return
    if again:
        directory = covering(out / "certs", scenario, phones).resolve()
    else:
        directory = make_authority(out / "certs", members(scenario, phones), hosts=hosts)
        (directory / f"{AUTHORITY}.key").unlink()  # nobody issues more for a run of its own
    try:
        yield directory.resolve()
    finally:
        spend(directory)


def covering(given: Path, scenario: Scenario, phones: tuple[str, ...]) -> Path:
    """``given``, if it holds a certificate for every peer of ``scenario`` in its role."""
    wanted = members(scenario, phones)
    held = members_of(given)
    for name, role in wanted.items():
        if name not in held:
            raise BusError(
                f"{given} holds no valid certificate for {role} {name!r}; "
                f"bearcat certs init {given} --scenario {scenario.name} issues the missing ones"
            )
        if held[name].role != role:
            raise BusError(f"the certificate of {name!r} in {given} is for a {held[name].role}, not a {role}")
    return given.resolve()


def spend(directory: Path) -> None:
    """Delete the private keys of a run's own authority: the run is over."""
    for key in directory.glob("*.key"):
        key.unlink(missing_ok=True)


def add_to(directory: Path, scenario: Scenario, phones: tuple[str, ...] = (), hosts: tuple[str, ...] = ()) -> dict:
    """Issue into ``directory`` (making its authority if it has none) a
    certificate for every peer of ``scenario`` it lacks, and the router's
    (the launcher's) again if it does not name every one of ``hosts``; which it issued."""
    wanted = members(scenario, phones)
    if not (directory / f"{AUTHORITY}.pem").exists():
        make_authority(directory, wanted, hosts=hosts)
        return wanted
    held = members_of(directory)
    missing = {name: role for name, role in wanted.items() if name not in held}
    add_members(directory, missing, hosts=hosts)
    named = () if LAUNCHER in missing else hosts_named(directory, LAUNCHER)
    if LAUNCHER not in missing and not set(hosts) <= set(named):
        add_members(directory, {LAUNCHER: "launcher"}, hosts=(*named, *hosts))
        missing[LAUNCHER] = "launcher"
    return missing
