"""The in-process bus that simulation runs on, with Zenoh's semantics.

Sessions put bytes on keys; subscribers declared with key expressions
(``*`` one chunk, ``**`` any number, matched by Zenoh's own rules) receive
``(key, payload, sender)`` for every matching put of every session,
including their own; liveliness tokens appear and vanish for liveliness
subscribers as they do on Zenoh (a closed session's tokens vanish with it).

Delivery goes through ``deliver(sender, receiver, key, payload, call)``,
where ``call(payload)`` runs the receiver's matching callbacks: by default
at once, in the caller's stack; the simulation runtime passes its own, which
hands the put to the receiver's netem shim and schedules what survives (and
any duplicate) in virtual time. Liveliness changes come through the same
hook with ``payload`` None.
Puts are best effort or reliable as on Zenoh, which in a single process
means the same thing: loss and delay come only from netem.
Who receives a key is worked out on its first put and kept until a session
opens, closes or subscribes: a game puts the same few dozen keys over and
over, and matching every subscription on every put was most of a put's cost.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import zenoh

from bearcat.bus.errors import BusError

log = logging.getLogger(__name__)

Callback = Callable[[str, bytes, str], None]
LivelinessCallback = Callable[[str, bool], None]


def _key_expr(text: str) -> zenoh.KeyExpr:
    try:
        return zenoh.KeyExpr(text)
    except zenoh.ZError:
        raise BusError(f"{text!r} is not a valid key expression") from None


Deliver = Callable[[str, str, str, "bytes | None", Callable[["bytes | None"], None]], None]


def deliver_now(sender: str, receiver: str, key: str, payload: bytes | None, call) -> None:
    call(payload)


class InProcessBus:
    def __init__(self, deliver: Deliver | None = None) -> None:
        self._deliver = deliver or deliver_now
        self._sessions: dict[str, LocalSession] = {}
        self._tokens: dict[str, str] = {}  # key -> owning session
        self._routes: dict[str, list[tuple[LocalSession, list[Callback]]]] = {}  # key -> who receives it

    def session(self, name: str) -> LocalSession:
        if name in self._sessions:
            raise BusError(f"a session named {name!r} is already open on this bus")
        s = LocalSession(self, name)
        self._sessions[name] = s
        self._routes.clear()
        return s

    @property
    def sessions(self) -> list[str]:
        return list(self._sessions)

    # The sessions call these.

    def _put(self, sender: str, key: str, payload: bytes) -> None:
        for receiver, callbacks in self._route(key):
            self._deliver(sender, receiver.name, key, payload, self._call(receiver, callbacks, key, sender))

    def _route(self, key: str) -> list[tuple[LocalSession, list[Callback]]]:
        """The sessions with a subscription matching ``key``, in the order they
        opened, each with its callbacks for it."""
        route = self._routes.get(key)
        if route is None:
            expr = _key_expr(key)
            route = []
            for receiver in self._sessions.values():
                callbacks = [cb for sub_expr, cb in receiver._subscribers if sub_expr.intersects(expr)]
                if callbacks:
                    route.append((receiver, callbacks))
            self._routes[key] = route
        return route

    @staticmethod
    def _call(receiver, callbacks, key, sender):
        def call(payload):
            for callback in callbacks:
                if receiver.closed:
                    return
                try:
                    callback(key, payload, sender)
                except Exception:
                    log.exception("subscriber of %s on %s raised", receiver.name, key)

        return call

    def _token(self, owner: str, key: str, alive: bool) -> None:
        if alive:
            if key in self._tokens:
                raise BusError(f"liveliness token {key!r} is already declared")
            self._tokens[key] = owner
        else:
            self._tokens.pop(key, None)
        expr = _key_expr(key)
        for receiver in list(self._sessions.values()):
            for sub_expr, callback in list(receiver._liveliness):
                if sub_expr.intersects(expr):
                    self._deliver(
                        owner, receiver.name, key, None, self._call_liveliness(receiver, callback, key, alive)
                    )

    @staticmethod
    def _call_liveliness(receiver, callback, key, alive):
        def call(_payload=None):
            if not receiver.closed:
                try:
                    callback(key, alive)
                except Exception:
                    log.exception("liveliness subscriber of %s on %s raised", receiver.name, key)

        return call

    def _alive(self, expr: str) -> list[str]:
        e = _key_expr(expr)
        return sorted(k for k in self._tokens if e.intersects(_key_expr(k)))

    def _close(self, session: LocalSession) -> None:
        for key in [k for k, owner in self._tokens.items() if owner == session.name]:
            self._token(session.name, key, False)
        self._sessions.pop(session.name, None)
        self._routes.clear()


class LocalSession:
    """One peer's session on an ``InProcessBus``."""

    def __init__(self, bus: InProcessBus, name: str) -> None:
        self.bus = bus
        self.name = name
        self.closed = False
        self._subscribers: list[tuple[zenoh.KeyExpr, Callback]] = []
        self._liveliness: list[tuple[zenoh.KeyExpr, LivelinessCallback]] = []

    def put(self, key: str, payload: bytes, *, reliable: bool = True) -> None:
        self._check_open()
        self.bus._put(self.name, key, bytes(payload))

    def subscribe(self, key_expr: str, callback: Callback) -> None:
        self._check_open()
        self._subscribers.append((_key_expr(key_expr), callback))
        self.bus._routes.clear()

    def declare_token(self, key: str) -> None:
        self._check_open()
        self.bus._token(self.name, key, True)

    def subscribe_liveliness(self, key_expr: str, callback: LivelinessCallback, *, history: bool = True) -> None:
        """``callback(key, alive)`` on every token matching ``key_expr`` that
        appears or vanishes; with ``history``, at once for those already alive."""
        self._check_open()
        expr = _key_expr(key_expr)
        self._liveliness.append((expr, callback))
        if history:
            for key in self.bus._alive(key_expr):
                owner = self.bus._tokens[key]
                self.bus._deliver(owner, self.name, key, None, self.bus._call_liveliness(self, callback, key, True))

    def alive(self, key_expr: str) -> list[str]:
        return self.bus._alive(key_expr)

    def close(self) -> None:
        if not self.closed:
            self.bus._close(self)
            self.closed = True

    def _check_open(self) -> None:
        if self.closed:
            raise BusError(f"session {self.name!r} is closed")
