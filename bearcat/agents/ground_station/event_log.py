"""The event log of a run: one JSON line per thing that happened to a message.

``sent`` lines carry the whole message, except in a log told to leave the
bodies of some kinds of key to another (``bodiless``: a live ground
station's own log leaves its guidance to the launcher's run-wide log, which
holds them all), whose ``sent`` lines of those kinds carry the message's
number (``seq``) and its size on the wire instead; ``received`` lines say
who got which message when; ``impaired`` lines say what the network did (delivered late
and by how much, duplicated, dropped and why, held in a dead zone), so an
analysis can tell a late fix from a lost one; ``outcome`` closes the log.
Lines are written as they happen, each with one system call, so a run that
dies loses nothing it had already recorded. A write the disk refuses (full,
read-only) loses that line and no more: the file is cut back to its last
whole line, the loss is counted (``lost``) and logged, and the game goes
on; the recording is never worth the game.

Lines are strict JSON, encoded and decoded by msgspec: a game writes a line
for every message it sends, receives or impairs, and the standard library's
encoder spent a third of a simulated game's time on them. A number that is
not finite, which JSON has no token for, is written as null; bus messages
never carry one (``bus.messages`` refuses them), and logs written with
``NaN`` or ``Infinity`` tokens before are still read.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Iterator
from pathlib import Path

import msgspec

from bearcat.bus import keys
from bearcat.bus.messages import Message
from bearcat.netem.shim import Impairment

log = logging.getLogger(__name__)

_encode = msgspec.json.Encoder().encode
_decode = msgspec.json.Decoder().decode


class EventLog:
    """Appends to ``path`` (JSON lines); with ``path`` None it only counts.
    ``last`` keeps the latest message sent on each key, what a peer
    restarted mid-game resumes from. A peer's log is opened to ``append``,
    so a restarted peer's log keeps what its first life recorded. What is
    sent on the kinds of key in ``bodiless`` is logged without its body."""

    def __init__(self, path: str | Path | None = None, *, append: bool = False, bodiless: tuple[str, ...] = ()) -> None:
        self.path = None if path is None else Path(path)
        self.bodiless = frozenset(bodiless)
        self.counts: dict[str, int] = {}
        self.last: dict[str, Message] = {}
        self.lost = 0  # lines the disk refused
        self.failure: str | None = None  # why the first of them was refused
        self._fd: int | None = None
        self._size = 0
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            mode = os.O_WRONLY | os.O_CREAT | (os.O_APPEND if append else os.O_TRUNC)
            self._fd = os.open(self.path, mode, 0o644)
            self._size = os.fstat(self._fd).st_size

    def sent(self, t: float, sender: str, key: str, message: Message, size: int | None = None) -> None:
        """``message`` went out on ``key``; ``size``: its payload's bytes, where known."""
        self.last[key] = message
        if not self._tally("sent"):
            return
        if self.bodiless and keys.parse(key).kind in self.bodiless:
            seq = getattr(message, "seq", None)
            self._write({"event": "sent", "t": t, "sender": sender, "key": key, "seq": seq, "size": size})
            return
        self._write({"event": "sent", "t": t, "sender": sender, "key": key, "message": msgspec.to_builtins(message)})

    def received(self, t: float, sender: str, receiver: str, key: str, seq: int | None = None) -> None:
        if self._tally("received"):
            self._write({"event": "received", "t": t, "sender": sender, "receiver": receiver, "key": key, "seq": seq})

    def refused(self, t: float, sender: str, receiver: str, key: str, reason: str) -> None:
        if self._tally("refused"):
            self._write(
                {"event": "refused", "t": t, "sender": sender, "receiver": receiver, "key": key, "reason": reason}
            )

    def impaired(self, record: Impairment) -> None:
        if not self._tally(f"impaired:{record.action}"):
            return
        self._write(
            {
                "event": "impaired",
                "t": record.sent,
                "sender": record.sender,
                "receiver": record.receiver,
                "key": record.key,
                "size": record.size,
                "action": record.action,
                "delay": record.delay,
                "reasons": list(record.reasons),
            }
        )

    def note(self, t: float, event: str, /, **fields) -> None:
        if self._tally(event):
            self._write({"event": event, "t": t, **fields})

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if self.lost:
            log.error("%s lost %d line(s) the disk refused: %s", self.path, self.lost, self.failure)

    def _tally(self, event: str) -> bool:
        """Count an ``event``; whether it has a file to go to. A log that only
        counts (the benchmarks', a study's that reads no log) builds no line."""
        self.counts[event] = self.counts.get(event, 0) + 1
        return self._fd is not None

    def _write(self, record: dict) -> None:
        """Append ``record`` (counted already) as one line."""
        fd = self._fd
        assert fd is not None  # only a log with a file writes
        line = _encode(record) + b"\n"
        try:
            written = os.write(fd, line)
            if written < len(line):
                raise OSError(f"only {written} of {len(line)} bytes written")
            self._size += written
        except OSError as exc:
            self._refused(fd, exc)

    def _refused(self, fd: int, exc: OSError) -> None:
        """Cut the file ``fd`` back to its last whole line and count the loss."""
        try:
            os.ftruncate(fd, self._size)
        except OSError:
            pass
        self.lost += 1
        if self.failure is None:
            self.failure = str(exc)
            log.error("%s: a line could not be written (%s); the game goes on, and losses are counted", self.path, exc)


def read_events(path: str | Path) -> list[dict]:
    """The records of an event log (a torn last line, from a run that died mid-write, is skipped)."""
    return list(iter_events(path))


def iter_events(path: str | Path) -> Iterator[dict]:
    """The records of an event log one by one, for logs too long to hold."""
    with open(path, "rb") as f:
        for line in f:
            try:
                yield _decode(line)
            except msgspec.DecodeError:
                try:
                    yield json.loads(line)  # NaN or Infinity, in a log written before lines were strict
                except ValueError:
                    return
