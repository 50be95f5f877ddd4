"""Zenoh endpoints and the hosts in them, read once and checked: ``PROTOCOL/HOST:PORT``.

A router on a field laptop listens on endpoints such as ``tls/0.0.0.0:7447``
(every interface) or ``tls/192.168.1.10:7447`` (one); a peer on another
machine connects to one naming an address of the laptop, which a ``tls/``
link checks against the names in the router's certificate. A host is an IP
address (IPv6 in brackets inside an endpoint) or a DNS name; anything else,
an unknown protocol or a port out of range is one sentence naming it.
"""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass

from bearcat.bus.errors import BusError

PROTOCOLS = ("tcp", "tls", "udp")
"""The links bearcat opens: tcp/, tls/ (mutual TLS, over TCP), and udp/ for best-effort traffic."""

WILDCARDS = ("0.0.0.0", "::")
"""Hosts that mean every interface of this machine: a router listens there, nobody connects there."""

_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")
_FORM = "PROTOCOL/HOST:PORT, e.g. tls/192.168.1.10:7447"


@dataclass(frozen=True)
class Endpoint:
    """A link's protocol, host (an address without brackets, or a DNS name) and port."""

    protocol: str
    host: str
    port: int

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.protocol}/{host}:{self.port}"

    @property
    def wildcard(self) -> bool:
        """Whether it names every interface rather than one address."""
        return self.host in WILDCARDS

    def at(self, host: str) -> Endpoint:
        """The same protocol and port at ``host``."""
        return Endpoint(self.protocol, host, self.port)


def parse_endpoint(text: str) -> Endpoint:
    """``text`` as an endpoint, or a sentence saying what is wrong with it."""
    if not isinstance(text, str):
        raise BusError(f"endpoint {text!r} is not of the form {_FORM}")
    protocol, slash, address = text.partition("/")
    host, colon, port = address.rpartition(":")
    if not slash or not colon:
        raise BusError(f"endpoint {text!r} is not of the form {_FORM}")
    if protocol not in PROTOCOLS:
        raise BusError(f"endpoint {text!r}: protocol {protocol!r} is not one of {', '.join(PROTOCOLS)}")
    if not port.isdigit() or int(port) > 65535:
        raise BusError(f"endpoint {text!r}: port {port!r} is not a number from 0 to 65535")
    bracketed = host.startswith("[") and host.endswith("]")
    if bracketed:
        host = host[1:-1]
    elif ":" in host:
        raise BusError(f"endpoint {text!r}: an IPv6 address goes in brackets, e.g. tls/[fe80::1]:7447")
    try:
        checked = check_host(host)
    except BusError as exc:
        raise BusError(f"endpoint {text!r}: {exc}") from None
    if bracketed and ":" not in checked:
        raise BusError(f"endpoint {text!r}: only an IPv6 address goes in brackets")
    return Endpoint(protocol, checked, int(port))


def check_host(text: str) -> str:
    """``text`` if it is an IP address or a DNS name (the form a certificate names), in its usual spelling."""
    try:
        return str(ipaddress.ip_address(text))
    except ValueError:
        pass
    labels = text.rstrip(".").split(".") if text else []
    if not labels or len(text) > 253 or not all(_LABEL.match(label) for label in labels):
        raise BusError(f"host {text!r} is neither an IP address nor a DNS name")
    if labels[-1].isdigit():  # 192.168.1 or 10.0.0.300: an address mistyped, not a name
        raise BusError(f"host {text!r} is not an IP address (and a DNS name does not end in a number)")
    return text.rstrip(".").lower()


def is_loopback(host: str) -> bool:
    """Whether ``host`` is this machine's loopback, which no other machine reaches."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def is_address(host: str) -> bool:
    """Whether ``host`` is an IP address (not a DNS name)."""
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True
