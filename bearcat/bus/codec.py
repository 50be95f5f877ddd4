"""One codec for every message: MessagePack through msgspec, strict both ways.

``decode`` checks, besides the schema, that a message is the kind its key
says and names the agent its key names, so a phone cannot publish fixes for
another agent by mistake. ``Inbox`` is what a peer decodes through: a bad
payload becomes a counted, logged drop with its reason and never an
exception in the peer.
"""

from __future__ import annotations

import logging
from collections import Counter

import msgspec

from bearcat.bus import keys
from bearcat.bus.errors import BusError
from bearcat.bus.messages import (
    AnyMessage,
    Control,
    Detection,
    FaultNotice,
    Fix,
    GameState,
    Guidance,
    Message,
    Truth,
    UavTask,
)

log = logging.getLogger(__name__)

# Bytes. Sized from the largest message the schema admits, so no message a
# sender may build is refused as oversized: a guidance whose region, boundary
# and possible each hold OUTLINE_POINTS points, with every other list full,
# encodes to about 245 KB, and the 256 KiB cap leaves a few per cent of margin.
# Real guidance is far smaller (measured: at most 8 KB in the search game on
# campus-250x200, 39 KB in open-loop, whose planned paths are the longest
# lines); the cap spares a peer from parsing anything bigger than a message can be.
MAX_PAYLOAD = 256 << 10
_ENCODER = msgspec.msgpack.Encoder()
_DECODER = msgspec.msgpack.Decoder(AnyMessage)

# The message type a key of each kind carries, and the field that must match the key's name.
_FOR_KIND = {
    "fix": (Fix, "agent"),
    "truth": (Truth, "agent"),
    "guidance": (Guidance, "agent"),
    "state": (GameState, None),
    "control": (Control, None),
    "fault": (FaultNotice, None),
    "uav-task": (UavTask, "uav"),
    "detection": (Detection, "uav"),
}


def encode(message: Message) -> bytes:
    if not isinstance(message, Message):
        raise BusError(f"only bus messages can be encoded, got {type(message).__name__}")
    return _ENCODER.encode(message)


class Refused(BusError):
    """A payload decoding refused; ``category`` is the short class of reason
    drops are counted under (oversized, undecodable, foreign key, wrong kind,
    wrong name)."""

    def __init__(self, category: str, reason: str) -> None:
        super().__init__(reason)
        self.category = category


def decode(payload: bytes, key: str | None = None) -> Message:
    """The message in ``payload``; with ``key``, also checked against it.
    Raises Refused with the reason for anything else."""
    if len(payload) > MAX_PAYLOAD:
        raise Refused("oversized", f"a payload of {len(payload)} bytes exceeds the {MAX_PAYLOAD}-byte limit")
    try:
        message = _DECODER.decode(payload)
    except msgspec.DecodeError as exc:
        raise Refused("undecodable", f"undecodable payload: {exc}") from None
    if key is not None:
        try:
            parsed = keys.parse(key)
        except BusError as exc:
            raise Refused("foreign key", str(exc)) from None
        expected = _FOR_KIND.get(parsed.kind)
        if expected is None:
            raise Refused("foreign key", f"key {key!r} carries no messages")
        kind, field = expected
        if not isinstance(message, kind):
            raise Refused(
                "wrong kind", f"a {type(message).__name__} on {key!r}, which carries {kind.__name__} messages"
            )
        if field is not None and getattr(message, field) != parsed.agent:
            raise Refused("wrong name", f"a {kind.__name__} for {getattr(message, field)!r} on {key!r}")
    return message


class Inbox:
    """Decodes what a peer receives and keeps count of what it had to drop.

    ``drops`` counts drops by a short reason class; the first drop of each
    class and every hundredth after it are logged with the full reason and
    the key, so a flood of garbage cannot flood the log too."""

    def __init__(self, owner: str = "peer") -> None:
        self.owner = owner
        self.received = 0
        self.drops: Counter[str] = Counter()

    def accept(self, key: str, payload: bytes) -> Message | None:
        self.received += 1
        try:
            return decode(bytes(payload), str(key))
        except Refused as exc:
            self._drop(str(key), exc.category, str(exc))
        except Exception as exc:
            self._drop(str(key), "unexpected", f"{type(exc).__name__}: {exc}")
        return None

    @property
    def dropped(self) -> int:
        return sum(self.drops.values())

    def _drop(self, key: str, cls: str, reason: str) -> None:
        self.drops[cls] += 1
        n = self.drops[cls]
        if n == 1 or n % 100 == 0:
            log.warning("%s dropped a message on %s (%s, %d so far): %s", self.owner, key, cls, n, reason)
