"""Why a link to a router did not open, in the words a person setting up a field can act on.

Zenoh says "unable to connect" whatever went wrong: nothing listens at the
address, the router's certificate is from another authority or does not
name the address connected to, or the router refused this peer's
certificate. Each needs a different fix on a different machine, so a
session that could not open tries the endpoint again by itself, with a
plain TCP connection and a TLS handshake presenting the same certificate,
and says which it was.
"""

from __future__ import annotations

import socket
import ssl
from pathlib import Path

from bearcat.bus.endpoints import Endpoint

TIMEOUT = 2.0  # s for the address to answer
REFUSAL_WAIT = 1.0  # s for a router to refuse a certificate once the handshake is done (TLS 1.3 says so late)


def why_unreachable(endpoint: Endpoint, identity: tuple[Path, Path, Path] | None) -> str:
    """What stands between this machine and a router at ``endpoint``, as a
    clause; ``identity`` is the authority, certificate and key a ``tls/``
    link presents (Zenoh's ``root_ca_certificate``, ``connect_certificate``
    and ``connect_private_key``)."""
    try:
        raw = socket.create_connection((endpoint.host, endpoint.port), timeout=TIMEOUT)
    except socket.gaierror:
        return f"no address is known for the name {endpoint.host}"
    except TimeoutError:
        return f"nothing answered within {TIMEOUT:g} s (a wrong address, or a firewall in the way)"
    except OSError as exc:
        return f"nothing answered there ({exc.strerror or exc})"
    with raw:
        if endpoint.protocol != "tls" or identity is None:
            return "something answered there, but not as a Zenoh router over " + endpoint.protocol
        return _handshake(raw, endpoint, *identity)


def _handshake(raw: socket.socket, endpoint: Endpoint, authority: Path, certificate: Path, key: Path) -> str:
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    context.load_verify_locations(authority)
    context.load_cert_chain(certificate, key)
    try:
        with context.wrap_socket(raw, server_hostname=endpoint.host) as link:
            link.settimeout(REFUSAL_WAIT)
            try:
                link.recv(1)
            except TimeoutError:
                return "the router took this peer's certificate, but Zenoh could not open a session over the link"
    except ssl.SSLCertVerificationError as exc:
        if "mismatch" in (exc.verify_message or ""):
            return (
                f"the router's certificate does not name {endpoint.host}: on the router's machine, "
                f"bearcat certs init DIR --scenario SCENARIO --host {endpoint.host} adds it"
            )
        return f"the router's certificate is not from the authority in {authority} ({exc.verify_message})"
    except (ssl.SSLError, ConnectionError) as exc:
        reason = getattr(exc, "reason", None) or exc.__class__.__name__
        return (
            f"the router refused this peer's certificate {certificate} ({reason}): it is not from "
            "the router's authority"
        )
    except OSError as exc:
        return f"the link broke during the TLS handshake ({exc.strerror or exc})"
    return "the router answered over TLS, but Zenoh could not open a session over the link"
