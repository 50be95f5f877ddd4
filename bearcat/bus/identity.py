"""Who is who on the bus: a certificate authority, one certificate per peer,
and the seal every message carries.

A game's peers share a directory made by ``make_authority``::

    DIR/ca.pem            the authority's certificate (everyone trusts it)
    DIR/ca.key            its key (only to issue more certificates; keep it off the field)
    DIR/NAME.pem          peer NAME's certificate: common name NAME, organisational unit its role
    DIR/NAME.key          its private key (EC P-256), readable by its owner only

The same key and certificate serve twice: as the peer's TLS identity on a
``--secure`` bus (the router's access control reads the common name), and to
sign each message it publishes. The second is what lets a receiver believe
the sender's name on any bus, secured or not: Zenoh hands a receiver the
attachment the sender chose, so a name alone proves nothing.

A seal is ``[sender, n, signature]`` in MessagePack, the signature ECDSA
P-256 / SHA-256 over the key, ``n`` and the payload. ``n`` grows with every
message the sender puts (nanoseconds of its wall clock, or one more than
the last), so a receiver refuses a recorded message played again: it takes
from each sender on each key only what is newer than what it already took.
"""

from __future__ import annotations

import datetime
import ipaddress
import os
import time
from dataclasses import dataclass
from pathlib import Path

import msgspec
from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from bearcat.bus import keys
from bearcat.bus.errors import BusError

ROLES = ("ground-station", "launcher", "walker", "phone", "uav")
"""A peer's role, in its certificate: what the access policy lets it publish and read."""

AUTHORITY = "ca"
VALIDITY = datetime.timedelta(days=365)
DEFAULT_HOSTS = ("localhost", "127.0.0.1")
_SIGNATURE = ec.ECDSA(hashes.SHA256())
_SEAL_ENCODER = msgspec.msgpack.Encoder()
_SEAL_DECODER = msgspec.msgpack.Decoder(tuple[str, int, bytes])
MAX_SEAL = 256  # bytes: a name, a counter and a DER signature fit in far less


class Refusal(BusError):
    """A message whose seal does not hold; ``category`` is the short class it is counted under."""

    def __init__(self, category: str, reason: str) -> None:
        super().__init__(reason)
        self.category = category


@dataclass(frozen=True)
class Member:
    """A peer the authority vouches for."""

    name: str
    role: str
    public_key: ec.EllipticCurvePublicKey


def make_authority(directory: Path | str, members: dict[str, str], *, hosts: tuple[str, ...] = ()) -> Path:
    """Write a new authority and a certificate for each of ``members`` (name ->
    role) into ``directory``; ``hosts`` are the names and addresses, beyond
    the loopback, that peers reach a listening peer at (a field laptop's
    address). Refuses a directory that already holds an authority: a second
    one would orphan every certificate issued by the first."""
    directory = Path(directory)
    if (directory / f"{AUTHORITY}.pem").exists():
        raise BusError(f"{directory} already holds a certificate authority; issue into it with add_members")
    if not directory.exists():
        directory.mkdir(mode=0o700, parents=True)  # a directory the user had keeps its own permissions
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "bearcat authority")])
    builder = _builder(subject, subject, key.public_key(), VALIDITY)
    builder = builder.add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True).add_extension(
        x509.KeyUsage(False, False, False, False, False, True, True, False, False), critical=True
    )  # certificate and CRL signing only
    _write(directory, AUTHORITY, builder.sign(key, hashes.SHA256()), key)
    add_members(directory, members, hosts=hosts)
    return directory


def add_members(directory: Path | str, members: dict[str, str], *, hosts: tuple[str, ...] = ()) -> None:
    """Issue a certificate and key for each of ``members`` (name -> role) from the authority in ``directory``."""
    directory = Path(directory)
    try:
        ca_key = serialization.load_pem_private_key((directory / f"{AUTHORITY}.key").read_bytes(), None)
        ca_cert = x509.load_pem_x509_certificate((directory / f"{AUTHORITY}.pem").read_bytes())
    except FileNotFoundError:
        raise BusError(f"{directory} holds no certificate authority with its key (ca.pem, ca.key)") from None
    if not isinstance(ca_key, ec.EllipticCurvePrivateKey):
        raise BusError(f"{directory / (AUTHORITY + '.key')} is not an EC key, as make_authority writes")
    lifetime = min(VALIDITY, ca_cert.not_valid_after_utc - datetime.datetime.now(datetime.UTC))
    for name, role in members.items():
        keys.check_name(name, "peer name")
        if name == AUTHORITY:
            raise BusError(f"a peer cannot be named {AUTHORITY!r}: that is the authority's file")
        if role not in ROLES:
            raise BusError(f"role {role!r} of {name!r} is not one of {', '.join(ROLES)}")
        key = ec.generate_private_key(ec.SECP256R1())
        subject = x509.Name(
            [
                x509.NameAttribute(NameOID.COMMON_NAME, name),
                x509.NameAttribute(NameOID.ORGANIZATIONAL_UNIT_NAME, role),
            ]
        )
        builder = _leaf(_builder(subject, ca_cert.subject, key.public_key(), lifetime), hosts)
        _write(directory, name, builder.sign(ca_key, hashes.SHA256()), key)


def self_signed(directory: Path, stem: str, common_name: str, hosts: tuple[str, ...], lifetime: datetime.timedelta):
    """A certificate that vouches for itself, naming ``hosts`` and the loopback
    (a web page's for one session); the paths of it and its key."""
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])
    _write(
        directory,
        stem,
        _leaf(_builder(subject, subject, key.public_key(), lifetime), hosts).sign(key, hashes.SHA256()),
        key,
    )
    return directory / f"{stem}.pem", directory / f"{stem}.key"


def _builder(subject: x509.Name, issuer: x509.Name, public_key, lifetime: datetime.timedelta):
    now = datetime.datetime.now(datetime.UTC)
    return (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(issuer)
        .public_key(public_key)
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))  # a peer whose clock is a little behind
        .not_valid_after(now + lifetime)
    )


def _leaf(builder: x509.CertificateBuilder, hosts: tuple[str, ...]) -> x509.CertificateBuilder:
    """A certificate that serves either end of a TLS link at the loopback and ``hosts``."""
    names = [_alternative(h) for h in dict.fromkeys((*DEFAULT_HOSTS, *hosts))]
    usage = [x509.oid.ExtendedKeyUsageOID.SERVER_AUTH, x509.oid.ExtendedKeyUsageOID.CLIENT_AUTH]
    return (
        builder.add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.SubjectAlternativeName(names), critical=False)
        .add_extension(x509.ExtendedKeyUsage(usage), critical=False)
    )


def hosts_named(directory: Path | str, name: str) -> tuple[str, ...]:
    """The names and addresses at which the certificate of peer ``name`` in
    ``directory`` serves TLS (what a ``tls/`` link to it checks the address
    it connected to against): the loopback and the ``hosts`` it was issued for."""
    path = Path(directory) / f"{name}.pem"
    try:
        cert = x509.load_pem_x509_certificate(path.read_bytes())
    except FileNotFoundError:
        raise BusError(f"{directory} holds no certificate for {name!r} ({name}.pem)") from None
    except ValueError:
        raise BusError(f"{path} is not a PEM certificate") from None
    try:
        names = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return ()
    return tuple(str(n.value) for n in names if isinstance(n, x509.DNSName | x509.IPAddress))


def _write(directory: Path, stem: str, cert: x509.Certificate, key: ec.EllipticCurvePrivateKey) -> None:
    _write_key(directory / f"{stem}.key", key)
    (directory / f"{stem}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))


def members_of(directory: Path | str) -> dict[str, Member]:
    """Every peer whose certificate in ``directory`` the authority there
    issued and that is valid now, by name. A certificate that fails is left
    out (a peer signing with it is refused as unknown), never trusted."""
    directory = Path(directory)
    try:
        ca_cert = x509.load_pem_x509_certificate((directory / f"{AUTHORITY}.pem").read_bytes())
    except FileNotFoundError:
        raise BusError(f"{directory} holds no certificate authority (ca.pem)") from None
    except ValueError:
        raise BusError(f"{directory / 'ca.pem'} is not a PEM certificate") from None
    now = datetime.datetime.now(datetime.UTC)
    found = {}
    for path in sorted(directory.glob("*.pem")):
        if path.stem == AUTHORITY:
            continue
        try:
            cert = x509.load_pem_x509_certificate(path.read_bytes())
            cert.verify_directly_issued_by(ca_cert)
        except (ValueError, TypeError, InvalidSignature):
            continue
        if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
            continue
        name, role = _attribute(cert, NameOID.COMMON_NAME), _attribute(cert, NameOID.ORGANIZATIONAL_UNIT_NAME)
        public_key = cert.public_key()
        if name != path.stem or role not in ROLES or not isinstance(public_key, ec.EllipticCurvePublicKey):
            continue
        found[name] = Member(name, role, public_key)
    return found


class Credentials:
    """Peer ``name``'s key and every member it may hear from, from the directory
    ``directory``: it seals what it sends and opens what it receives."""

    def __init__(self, directory: Path | str, name: str) -> None:
        self.directory = Path(directory)
        self.name = keys.check_name(name, "peer name")
        self.members = members_of(self.directory)
        if name not in self.members:
            raise BusError(f"{self.directory} holds no valid certificate for {name!r} ({name}.pem from its ca.pem)")
        try:
            key = serialization.load_pem_private_key((self.directory / f"{name}.key").read_bytes(), None)
        except FileNotFoundError:
            raise BusError(f"{self.directory} holds no key for {name!r} ({name}.key)") from None
        if (
            not isinstance(key, ec.EllipticCurvePrivateKey)
            or key.public_key().public_numbers() != self.members[name].public_key.public_numbers()
        ):
            raise BusError(f"{self.directory / (name + '.key')} is not the key of {name}.pem")
        self.role = self.members[name].role
        self._key = key
        self._n = 0

    @property
    def certificate(self) -> Path:
        return self.directory / f"{self.name}.pem"

    @property
    def private_key(self) -> Path:
        return self.directory / f"{self.name}.key"

    @property
    def authority(self) -> Path:
        return self.directory / f"{AUTHORITY}.pem"

    def seal(self, key: str, payload: bytes) -> bytes:
        """The attachment that proves this peer put ``payload`` on ``key`` now."""
        self._n = max(self._n + 1, time.time_ns())
        signature = self._key.sign(_signed(key, self._n, payload), _SIGNATURE)
        return _SEAL_ENCODER.encode((self.name, self._n, signature))

    def open(self, key: str, payload: bytes, attachment: bytes | None, admit=None) -> tuple[Member, int]:
        """Who sealed ``payload`` on ``key`` and their count, or a Refusal
        saying why nobody provably did. ``admit(member, n)`` may refuse the
        claim first: the checks that cost nothing go before the one that
        costs a signature's verification."""
        if not attachment:
            raise Refusal("unsigned", f"a message on {key} carries no seal")
        if len(attachment) > MAX_SEAL:
            raise Refusal("bad seal", f"a seal of {len(attachment)} bytes on {key}")
        try:
            sender, n, signature = _SEAL_DECODER.decode(attachment)
        except msgspec.DecodeError:
            raise Refusal("bad seal", f"a message on {key} carries something that is not a seal") from None
        member = self.members.get(sender)
        if member is None:
            raise Refusal(
                "unknown sender", f"a message on {key} claims to be from {sender[:64]!r}, who holds no certificate"
            )
        if admit is not None:
            admit(member, n)
        try:
            member.public_key.verify(signature, _signed(key, n, payload), _SIGNATURE)
        except (InvalidSignature, ValueError):
            raise Refusal("forged", f"a message on {key} claims to be from {sender!r}, who did not sign it") from None
        return member, n


def _signed(key: str, n: int, payload: bytes) -> bytes:
    return b"%s\0%d\0%s" % (key.encode(), n, payload)


def _attribute(cert: x509.Certificate, oid) -> str | None:
    values = cert.subject.get_attributes_for_oid(oid)
    return str(values[0].value) if values else None


def _alternative(host: str) -> x509.GeneralName:
    try:
        return x509.IPAddress(ipaddress.ip_address(host))
    except ValueError:
        return x509.DNSName(host)


def _write_key(path: Path, key: ec.EllipticCurvePrivateKey) -> None:
    data = key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "wb") as file:
        file.write(data)
