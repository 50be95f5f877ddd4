"""Zenoh sessions for live runs, with the interface of ``LocalSession``.

Set-up that works on a single host and across machines: peer mode, every
peer listening (Zenoh forwards only to peers that listen), multicast
scouting off (on a host whose loopback has no multicast it scouts out of the
wrong interface, slowly), explicit endpoints to connect to, and a 1 s link
lease so a frozen peer's liveliness vanishes within about a second.

Fixes go best effort with congestion control DROP (a lost fix is lost, not
delivered late in a burst); everything else reliable with BLOCK.

Every put carries its sender's name as its attachment, which is how the
receiver's netem shim knows the directed link a message came over. A
session with ``credentials`` (``bus.identity``) seals each put instead, and
hands on only the samples whose seal holds, whose sender the access policy
lets publish on that key (``bus.policy``), and that are newer than the last
that sender put there; the rest are counted, logged and reported to
``on_refused`` with the name they claimed. A session without credentials
believes every name it is told: it is for a private host only.

Over TCP a best-effort put is still retransmitted by TCP: a lost packet
stalls everything behind it and then arrives in a burst. A session given a
second configuration for best-effort traffic (``best_effort``, typically a
client of the same router over ``udp/``) sends fixes, guidance and truth
there, where a lost packet is a lost fix, and everything else over the
first; it subscribes to each kind of key on the session that kind travels
on, so no message arrives twice.

Subscriber callbacks run on a Zenoh-owned thread: they must be short (the
live runtime's hand the sample to its asyncio loop and return), and an
exception in one is logged and counted in ``callback_errors``, never lost
silently.

A session is a context manager, as zenoh's own are (``with ZenohSession(...)
as session:``), so whoever opens one closes it on every path out. Opening one
that cannot reach its endpoints (a client whose router is not there, or
whose TLS handshake fails) raises a ``BusError`` that names them and says
why (``bus.probe``); one that cannot listen where it is told names the
endpoint and the reason. ``links()`` says where each session linked to
this one came from, and on ``tls/`` whose certificate it presented (the
launcher's report of who joined from where).
"""

from __future__ import annotations

import json
import logging
import re
import threading
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import msgspec
import zenoh

from bearcat.bus import keys
from bearcat.bus.endpoints import parse_endpoint
from bearcat.bus.errors import BusError
from bearcat.bus.identity import Credentials, Refusal
from bearcat.bus.inprocess import Callback, LivelinessCallback
from bearcat.bus.policy import may_publish
from bearcat.bus.probe import why_unreachable

log = logging.getLogger(__name__)

LOOPBACK_LISTEN = "tcp/127.0.0.1:0"
LEASE_MS = 1000
# Zenoh does not retransmit its opening handshake over udp/: one lost packet
# fails the attempt after the handshake timeout. A client over udp/ tries
# again, for this long in all (measured under 3g-degraded: 5 of 12 single
# attempts failed; with retries all 12 opened, the slowest in 22 s).
DATAGRAM_CONNECT_MS = 45_000
DATAGRAM_HANDSHAKE_MS = 2500
DATAGRAM_RETRY = {"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}


def config(
    *,
    listen: list[str] | None = None,
    connect: list[str] | None = None,
    mode: str = "peer",
    multicast: bool = False,
    lease_ms: int = LEASE_MS,
    tls: Credentials | None = None,
    access: dict | None = None,
) -> zenoh.Config:
    """A Zenoh configuration; ``listen`` defaults to an ephemeral loopback port.
    With ``tls``, its ``tls/`` links present that peer's certificate and
    accept only peers whose certificates its authority issued (mutual TLS);
    ``access`` is a router's access control (``bus.access``)."""
    if mode not in ("peer", "client", "router"):
        raise BusError(f"zenoh mode {mode!r} is not peer, client or router")
    listen = [LOOPBACK_LISTEN] if listen is None else list(listen)
    connect = list(connect or [])
    for endpoint in (*listen, *connect):
        parse_endpoint(endpoint)
    c = zenoh.Config()
    try:
        c.insert_json5("mode", json.dumps(mode))
        c.insert_json5("scouting/multicast/enabled", json.dumps(bool(multicast)))
        c.insert_json5("listen/endpoints", json.dumps(listen))
        c.insert_json5("connect/endpoints", json.dumps(connect))
        c.insert_json5("transport/link/tx/lease", json.dumps(int(lease_ms)))
        c.insert_json5("timestamping/enabled", "true")
        if tls is not None:
            c.insert_json5("transport/link/tls", json.dumps(_mutual_tls(tls)))
        if access is not None:
            c.insert_json5("access_control", json.dumps(access))
        if connect and all(endpoint.startswith("udp/") for endpoint in connect):
            c.insert_json5("connect/timeout_ms", json.dumps(DATAGRAM_CONNECT_MS))
            c.insert_json5("connect/retry", json.dumps(DATAGRAM_RETRY))
            c.insert_json5("transport/unicast/open_timeout", json.dumps(DATAGRAM_HANDSHAKE_MS))
    except zenoh.ZError as exc:
        raise BusError(f"zenoh rejected the configuration: {exc}") from None
    return c


@dataclass(frozen=True)
class Link:
    """A link of a session to another: from where (``remote``, the endpoint
    of the other end), in on which ``interfaces``, and on ``tls/`` the
    common name of the certificate the other end presented."""

    remote: str
    interfaces: tuple[str, ...]
    certificate: str | None


Refused = Callable[[str, str, str, str], None]
"""``refused(key, claimed_sender, category, reason)``: a sample a sealed session would not hand on."""


class ZenohSession:
    """One peer's Zenoh session, named ``name`` (the sender id on its puts);
    with ``best_effort``, a second one for the best-effort kinds of key; with
    ``credentials``, sealed both ways."""

    def __init__(
        self,
        name: str,
        zconfig: zenoh.Config | None = None,
        *,
        best_effort: zenoh.Config | None = None,
        credentials: Credentials | None = None,
    ) -> None:
        self.name = keys.check_name(name, "session name")
        if credentials is not None and credentials.name != self.name:
            raise BusError(f"session {name!r} cannot sign with the credentials of {credentials.name!r}")
        self.credentials = credentials
        self.refusals: Counter[str] = Counter()
        self.on_refused: Refused | None = None  # told of each refusal, on Zenoh's thread
        self.closed = False
        self.callback_errors = 0
        self._lock = threading.Lock()
        self._opened: list[zenoh.Session] = []
        try:
            self._session = self._open(zconfig if zconfig is not None else config())
            self._best_effort = self._session if best_effort is None else self._open(best_effort)
        except BusError:
            self._close_sessions()
            raise
        self._publishers: dict[tuple[str, bool], zenoh.Publisher] = {}
        self._declared: list = []  # subscribers and tokens, undeclared on close
        self._tokens: dict[str, zenoh.LivelinessToken] = {}
        self._attachment = self.name.encode()

    def __enter__(self) -> ZenohSession:
        return self

    def __exit__(self, *_exc) -> None:
        self.close()

    def put(self, key: str, payload: bytes, *, reliable: bool = True) -> None:
        self._check_open()
        publisher = self._publishers.get((key, reliable))
        if publisher is None:
            publisher = (self._session if reliable else self._best_effort).declare_publisher(
                key,
                reliability=zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT,
                congestion_control=zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP,
            )
            self._publishers[(key, reliable)] = publisher
        payload = bytes(payload)
        publisher.put(payload, attachment=self._seal(key, payload))

    def subscribe(self, key_expr: str, callback: Callback) -> None:
        """Call ``callback(key, payload, sender)`` for every sample on ``key_expr``."""
        self._check_open()
        if self._best_effort is self._session:
            self._declare_subscriber(self._session, key_expr, callback, lambda key: True)
            return
        reliable, best_effort = _reliabilities(key_expr)
        if reliable:
            self._declare_subscriber(self._session, key_expr, callback, _travels_reliably)
        if best_effort:
            self._declare_subscriber(self._best_effort, key_expr, callback, lambda key: not _travels_reliably(key))

    def _declare_subscriber(self, session, key_expr: str, callback: Callback, travels_here) -> None:
        """A subscriber on ``session`` that passes on the samples whose key
        ``travels_here``: the same sample reaches both sessions of a peer
        subscribed on both, and only one of them may deliver it."""

        newest: dict[tuple[str, str], int] = {}  # (sender, key) -> the count of the last sample taken

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                key = str(sample.key_expr)
                if not travels_here(key):
                    return
                payload = sample.payload.to_bytes()
                sender = self._sender(key, payload, sample.attachment, newest)
                if sender is not None:
                    callback(key, payload, sender)
            except Exception:
                self._callback_failed(key_expr)

        self._declared.append(session.declare_subscriber(key_expr, zenoh.handlers.Callback(on_sample)))

    def declare_token(self, key: str) -> None:
        self._check_open()
        token = self._tokens[key] = self._session.liveliness().declare_token(key)
        self._declared.append(token)

    def withdraw_token(self, key: str) -> None:
        """Undeclare the token on ``key``: to the others its holder is gone, though the session stands."""
        token = self._tokens.pop(key)
        self._declared.remove(token)
        token.undeclare()

    def subscribe_liveliness(self, key_expr: str, callback: LivelinessCallback, *, history: bool = True) -> None:
        self._check_open()

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                callback(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)
            except Exception:
                self._callback_failed(key_expr)

        subscriber = self._session.liveliness().declare_subscriber(
            key_expr, zenoh.handlers.Callback(on_sample), history=history
        )
        self._declared.append(subscriber)

    def serve(self, key: str, reply) -> None:
        """Answer queries on ``key`` with the bytes ``reply()`` returns (the
        ground station serves its map and scenario this way, a peer started
        elsewhere its log)."""
        self._check_open()

        def on_query(query: zenoh.Query) -> None:
            try:
                payload = bytes(reply())
                query.reply(key, payload, attachment=self._seal(key, payload))
            except Exception:
                self._callback_failed(key)

        self._declared.append(self._session.declare_queryable(key, zenoh.handlers.Callback(on_query)))

    def fetch(self, key: str, timeout: float = 2.0) -> bytes | None:
        """The first answer to a query on ``key``, None if nobody answers in time."""
        answer = self.ask(key, timeout)
        return None if answer is None else answer[0]

    def ask(self, key: str, timeout: float = 2.0) -> tuple[bytes, str] | None:
        """The first answer to a query on ``key`` and who gave it (proven, on a
        sealed session; claimed, on one without credentials), None if nobody
        answers in time."""
        self._check_open()
        for reply in self._session.get(key, timeout=timeout):
            if reply.ok is not None:
                payload = reply.ok.payload.to_bytes()
                sender = self._sender(key, payload, reply.ok.attachment, {})
                if sender is not None:
                    return payload, sender
        return None

    def links(self, timeout: float = 1.0) -> list[Link]:
        """The links this session holds to other machines' and processes' sessions, from its own admin space."""
        self._check_open()
        found = []
        for reply in self._session.get(f"@/{self._session.zid()}/session/transport/unicast/*/link/*", timeout=timeout):
            if reply.ok is None:
                continue
            try:
                link = json.loads(reply.ok.payload.to_string())
                found.append(
                    Link(
                        remote=str(link["dst"]),
                        interfaces=tuple(link.get("interfaces") or ()),
                        certificate=link.get("auth_identifier"),
                    )
                )
            except (ValueError, KeyError, TypeError):
                log.warning("session %s: a link it could not read: %r", self.name, reply.ok.payload.to_bytes()[:200])
        return found

    def alive(self, key_expr: str, timeout: float = 1.0) -> list[str]:
        self._check_open()
        replies = self._session.liveliness().get(key_expr, timeout=timeout)
        return sorted(str(r.ok.key_expr) for r in replies if r.ok is not None)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        for entity in reversed(self._declared):
            try:
                entity.undeclare()
            except zenoh.ZError:
                pass
        self._close_sessions()

    def _open(self, zconfig: zenoh.Config) -> zenoh.Session:
        try:
            session = zenoh.open(zconfig)
        except zenoh.ZError as exc:
            raise BusError(_refusal(self.name, zconfig, exc)) from None
        self._opened.append(session)
        return session

    def _close_sessions(self) -> None:
        for session in reversed(self._opened):
            try:
                session.close()
            except zenoh.ZError as exc:  # a peer that vanished without a goodbye makes the close time out
                log.warning("session %s closed without every goodbye: %s", self.name, exc)
        self._opened.clear()

    def _seal(self, key: str, payload: bytes) -> bytes:
        if self.credentials is None:
            return self._attachment
        return self.credentials.seal(key, payload)

    def _sender(self, key: str, payload: bytes, attachment, newest: dict) -> str | None:
        """Who put ``payload`` on ``key``, or None when a sealed session cannot
        believe anyone did (the refusal is counted, logged and reported)."""
        attachment = attachment.to_bytes() if attachment is not None else b""
        if self.credentials is None:
            return attachment.decode("utf-8", "replace")

        def admit(member, n):
            if not may_publish(member.role, member.name, key):
                raise Refusal("not allowed", f"{member.role} {member.name!r} may not publish on {key}")
            if n <= newest.get((member.name, key), -1):
                raise Refusal("replayed", f"a message on {key} from {member.name!r} older than one already taken")

        try:
            member, n = self.credentials.open(key, payload, attachment, admit)
            with self._lock:
                admit(member, n)  # again: another sample from the same sender may have been taken meanwhile
                newest[(member.name, key)] = n
            return member.name
        except Refusal as refusal:
            self._refuse(key, attachment, refusal)
            return None

    def _refuse(self, key: str, attachment: bytes, refusal: Refusal) -> None:
        with self._lock:
            self.refusals[refusal.category] += 1
            n = self.refusals[refusal.category]
        if n == 1 or n % 100 == 0:
            log.warning("%s refused a message (%s, %d so far): %s", self.name, refusal.category, n, refusal)
        if self.on_refused is not None:
            self.on_refused(key, _claimed(attachment), refusal.category, str(refusal))

    def _callback_failed(self, key_expr: str) -> None:
        with self._lock:
            self.callback_errors += 1
        log.exception("a callback of %s on %s raised", self.name, key_expr)

    def _check_open(self) -> None:
        if self.closed:
            raise BusError(f"session {self.name!r} is closed")


def _mutual_tls(credentials: Credentials) -> dict:
    """Zenoh's TLS link settings for a peer that presents its certificate both ways and trusts only its authority."""
    return {
        "root_ca_certificate": str(credentials.authority),
        "enable_mtls": True,
        "listen_certificate": str(credentials.certificate),
        "listen_private_key": str(credentials.private_key),
        "connect_certificate": str(credentials.certificate),
        "connect_private_key": str(credentials.private_key),
    }


def _claimed(attachment: bytes) -> str:
    """The sender an attachment names, whatever it is (for the record of a refusal)."""
    try:
        name = msgspec.msgpack.decode(attachment)[0]
    except (msgspec.DecodeError, TypeError, IndexError, KeyError):
        name = attachment.decode("utf-8", "replace")
    return name[:64] if isinstance(name, str) else "?"


def best_effort_endpoint(endpoint: str) -> str:
    """The ``udp/`` endpoint at the address of ``endpoint``: where a router
    listening on both takes best-effort traffic."""
    _, _, address = endpoint.partition("/")
    return f"udp/{address}"


def _travels_reliably(key: str) -> bool:
    """Whether ``key`` goes on the reliable session (anything not a game key of a best-effort kind)."""
    try:
        return keys.reliable(key)
    except BusError:
        return True


def _reliabilities(key_expr: str) -> tuple[bool, bool]:
    """Whether ``key_expr`` can match keys that travel reliably, and keys that travel best effort."""
    expr = zenoh.KeyExpr(key_expr)
    matches = {kind: expr.intersects(zenoh.KeyExpr(keys.any_game(kind))) for kind in keys.KINDS}
    best_effort = any(matches[kind] for kind in keys.BEST_EFFORT_KINDS)
    reliable = any(hit for kind, hit in matches.items() if kind not in keys.BEST_EFFORT_KINDS) or not best_effort
    return reliable, best_effort


_LISTEN_ERRORS = {
    98: "another program listens there already (another bearcat run?)",
    99: "no interface of this machine has that address (ip address lists them)",
    13: "a port below 1024 needs root",
}


def _refusal(name: str, zconfig: zenoh.Config, exc: zenoh.ZError) -> str:
    """Why zenoh would not open session ``name``, as one sentence naming the endpoints."""
    text = re.sub(r"\s*at /\S+\.rs:\d+\.?", "", str(exc)).strip()
    connect = _setting(zconfig, "connect/endpoints") or []
    if text.startswith("Unable to connect") and connect:
        tls = _setting(zconfig, "transport/link/tls") or {}
        ca, cert, key = (
            str(tls.get(k) or "") for k in ("root_ca_certificate", "connect_certificate", "connect_private_key")
        )
        identity = (Path(ca), Path(cert), Path(key)) if ca and cert and key else None
        reasons = [f"{e}: {why_unreachable(parse_endpoint(e), identity)}" for e in connect]
        return f"session {name!r} could not connect to {'; nor to '.join(reasons)}"
    if text.startswith("No peer specified"):
        return f"session {name!r} is a client with no endpoint to connect to"
    listener = re.search(r"listener (?:bound to|on) (\S+?):? .*\(os error (\d+)\)", text)
    if listener is not None:
        where, errno = listener.group(1), int(listener.group(2))
        listen = _setting(zconfig, "listen/endpoints") or []
        where = next((e for e in listen if e.endswith("/" + where.rpartition("/")[2])), where)
        why = _LISTEN_ERRORS.get(errno, text.rsplit(": ", 1)[-1])
        return f"session {name!r} cannot listen on {where}: {why}"
    return f"zenoh could not open session {name!r}: {text}"


def _setting(zconfig: zenoh.Config, path: str):
    """The JSON value at ``path`` of a configuration, None where it has none."""
    try:
        return json.loads(zconfig.get_json(path))
    except (zenoh.ZError, ValueError):
        return None
