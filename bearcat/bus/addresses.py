"""The addresses at which another machine on the same network reaches this one.

A server listening on every interface (``0.0.0.0``) still has to tell a
phone or a peer elsewhere one address to use. In the field the laptop is
often a hotspot with no way out, so no default route: then the address of
an interface that is up serves, and the loopback, which no other machine
reaches, never does. IPv4 only, read from the kernel (Linux).
"""

from __future__ import annotations

import fcntl
import socket
import struct

from bearcat.bus.endpoints import WILDCARDS, is_loopback
from bearcat.bus.errors import BusError

_SIOCGIFFLAGS = 0x8913
_SIOCGIFADDR = 0x8915
_IFF_UP = 0x1
_IFF_LOOPBACK = 0x8


def local_addresses() -> tuple[str, ...]:
    """The IPv4 address of each interface of this machine that is up, the loopback left out."""
    found = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        for _, name in socket.if_nameindex():
            request = struct.pack("256s", name.encode()[:15])
            try:
                flags = struct.unpack("H", fcntl.ioctl(probe, _SIOCGIFFLAGS, request)[16:18])[0]
                if not flags & _IFF_UP or flags & _IFF_LOOPBACK:
                    continue
                found.append(socket.inet_ntoa(fcntl.ioctl(probe, _SIOCGIFADDR, request)[20:24]))
            except OSError:  # no IPv4 address on it, or it went away meanwhile
                continue
    return tuple(dict.fromkeys(found))


def is_local(address: str) -> bool:
    """Whether ``address`` is one of this machine's, which a server can listen on."""
    family = socket.AF_INET6 if ":" in address else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        try:
            probe.bind((address, 0))
        except OSError:
            return False
    return True


def reachable(host: str) -> str:
    """The address a phone or peer on the same network reaches a server
    listening at ``host`` at: ``host`` itself unless it is every interface;
    else the one this machine's default route leaves by (a datagram
    socket's connect sends nothing), else that of the first interface up."""
    if host not in (*WILDCARDS, ""):
        return host
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("10.255.255.255", 1))
            routed = probe.getsockname()[0]
        except OSError:  # no default route: a hotspot with no way out
            routed = None
    if routed is not None and not is_loopback(routed):
        return routed
    found = local_addresses()
    if not found:
        raise BusError(
            "this machine has no network address but the loopback, which no phone or other machine reaches: "
            "join the field's network first, or name the loopback yourself (behind a tunnel)"
        )
    return found[0]
