"""Peers on other machines: where the launcher's router takes them, what
its certificate must name, what they are told, and who came from where.

In the field the ground station's laptop runs the launcher; a drone's
companion computer, a second laptop or an observer's tablet run peers of
their own and connect to its router over the field's network. The router
listens on the endpoints ``bearcat run --listen`` names besides its
loopback one: ``tls/`` on a ``--secure`` run, where a peer checks the
address it connected to against the names in the router's certificate,
``tcp/`` (and ``udp/`` at the same address, for best-effort traffic) on an
unsecured one. An endpoint on every interface (``0.0.0.0``) is reached at
each address of the laptop, and on a secure run only at those its
certificate names.

All of it is pure: the launcher hands in this machine's addresses, the
names in the router's certificate and the router's links.
"""

from __future__ import annotations

from dataclasses import dataclass

from bearcat.bus.endpoints import WILDCARDS, Endpoint, is_address, is_loopback, parse_endpoint
from bearcat.bus.errors import BusError
from bearcat.bus.zenoh_session import best_effort_endpoint


def check_listen(listen: tuple[Endpoint, ...], *, secure: bool) -> None:
    """A sentence for a ``--listen`` endpoint the router cannot take peers on."""
    for endpoint in listen:
        wanted = "tls" if secure else "tcp"
        if endpoint.protocol != wanted:
            why = (
                "a --secure router takes tls/ links only"
                if secure
                else "an unsecured router takes tcp/ links (and udp/ at the same address by itself); tls/ needs "
                "--secure"
            )
            raise BusError(f"--listen {endpoint}: {why}, e.g. {Endpoint(wanted, endpoint.host, endpoint.port)}")
        if not is_address(endpoint.host):
            raise BusError(f"--listen {endpoint}: a router listens on an address of this machine, not on a name")
        if endpoint.port == 0:
            raise BusError(f"--listen {endpoint}: peers elsewhere need a port they know; name one, e.g. 7447")


def router_endpoints(listen: tuple[Endpoint, ...], *, secure: bool) -> list[str]:
    """What the router listens on for peers elsewhere: each of ``listen``, with its ``udp/`` twin when unsecured."""
    found = []
    for endpoint in listen:
        found.append(str(endpoint))
        if not secure:
            found.append(best_effort_endpoint(str(endpoint)))
    return found


def hosts(listen: tuple[Endpoint, ...], addresses: tuple[str, ...]) -> tuple[str, ...]:
    """The addresses peers elsewhere reach the router at, which a run's own
    certificate names: each endpoint's, and this machine's ``addresses``
    for one on every interface."""
    found: list[str] = []
    for endpoint in listen:
        found += addresses if endpoint.wildcard else [endpoint.host]
    return tuple(dict.fromkeys(found))


def reachable_at(
    listen: tuple[Endpoint, ...], addresses: tuple[str, ...], named: tuple[str, ...] | None = None
) -> list[Endpoint]:
    """The endpoints a peer on another machine connects to: each of
    ``listen``, one on every interface at each of this machine's
    ``addresses``. With ``named`` (a secure run: the names in the router's
    certificate), only those the certificate names, and a wildcard's at
    the DNS names it names too."""
    found: list[Endpoint] = []
    for endpoint in listen:
        if not endpoint.wildcard:
            found.append(endpoint)
            continue
        at = list(addresses)
        if named is not None:
            at = [a for a in addresses if a in named] + [n for n in named if not is_address(n) and not is_loopback(n)]
        found += [endpoint.at(host) for host in at]
    return [e for e in found if named is None or e.host in named]


def uncovered(listen: tuple[Endpoint, ...], addresses: tuple[str, ...], named: tuple[str, ...], where: str) -> None:
    """A sentence for a secure run whose router certificate (``where``,
    naming ``named``) would fail every peer elsewhere at one of ``listen``."""
    for endpoint in listen:
        if endpoint.wildcard:
            if not reachable_at((endpoint,), addresses, named):
                raise BusError(
                    f"the router's certificate {where} names none of this machine's addresses "
                    f"({', '.join(addresses) or 'none but the loopback'}), so no peer elsewhere could trust it on "
                    f"--listen {endpoint}: bearcat certs init DIR --scenario SCENARIO --host ADDRESS adds one"
                )
        elif endpoint.host not in named:
            raise BusError(
                f"the router's certificate {where} does not name {endpoint.host}, where --listen {endpoint} takes "
                f"peers from other machines: bearcat certs init DIR --scenario SCENARIO --host {endpoint.host} "
                "adds it"
            )


def link_host(host: str, listen: tuple[Endpoint, ...]) -> str | None:
    """The address to name in the link to a page served at ``host``:
    ``host`` itself, unless it is every interface; then the first address
    the router takes other machines at, which is on the field's network;
    None when neither says."""
    if host not in (*WILDCARDS, ""):
        return host
    return next((e.host for e in listen if not e.wildcard and not is_loopback(e.host)), None)


@dataclass(frozen=True)
class Arrival:
    """A session that joined the router from another machine: the name its
    certificate gave (None on an unsecured link, which does not say), the
    address it came from, and the interface it came in on."""

    name: str | None
    address: str
    interface: str | None

    def describe(self) -> str:
        who = self.name or "a peer (an unsecured link does not say who)"
        return f"{who} joined from {self.address}" + (f" on {self.interface}" if self.interface else "")


def arrivals(links, seen: set[Arrival], by_hand: frozenset[str] = frozenset()) -> list[Arrival]:
    """The arrivals among the router's ``links`` (``ZenohSession.links``)
    that are not in ``seen``, which takes them in: those from other
    machines, and those over the loopback whose certificate names one of
    the peers a person starts here (``by_hand``)."""
    new = []
    for link in links:
        try:
            remote = parse_endpoint(link.remote)
        except BusError:
            continue
        if is_loopback(remote.host) and link.certificate not in by_hand:
            continue
        arrival = Arrival(link.certificate, remote.host, link.interfaces[0] if link.interfaces else None)
        if arrival not in seen:
            seen.add(arrival)
            new.append(arrival)
    return new
