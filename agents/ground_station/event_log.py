"""The event log of a run: one JSON line per thing that happened to a message.

``sent`` lines carry the whole message; ``received`` lines say who got which
message when; ``impaired`` lines say what the network did (delivered late
and by how much, duplicated, dropped and why, held in a dead zone), so an
analysis can tell a late fix from a lost one; ``outcome`` closes the log.
Lines are written as they happen and flushed, so a run that dies loses
nothing it had already recorded.
"""

from __future__ import annotations

import json
from pathlib import Path

import msgspec

from bearcat.bus.messages import Message
from bearcat.netem.shim import Impairment


class EventLog:
    """Appends to ``path`` (JSON lines); with ``path`` None it only counts.
    ``last`` keeps the latest message each sender sent on each key, what a
    peer restarted mid-game resumes from."""

    def __init__(self, path: str | Path | None = None) -> None:
        self.path = None if path is None else Path(path)
        self.counts: dict[str, int] = {}
        self.last: dict[tuple[str, str], Message] = {}
        self._file = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "w", encoding="utf-8")  # noqa: SIM115 (open for the log's lifetime)

    def sent(self, t: float, sender: str, key: str, message: Message) -> None:
        self.last[(sender, key)] = message
        self._write({"event": "sent", "t": t, "sender": sender, "key": key, "message": msgspec.to_builtins(message)})

    def received(self, t: float, sender: str, receiver: str, key: str, seq: int | None = None) -> None:
        self._write({"event": "received", "t": t, "sender": sender, "receiver": receiver, "key": key, "seq": seq})

    def refused(self, t: float, sender: str, receiver: str, key: str, reason: str) -> None:
        self._write({"event": "refused", "t": t, "sender": sender, "receiver": receiver, "key": key, "reason": reason})

    def impaired(self, record: Impairment) -> None:
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

    def note(self, t: float, what: str, **fields) -> None:
        self._write({"event": what, "t": t, **fields})

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def _write(self, record: dict) -> None:
        event = record["event"] if record["event"] != "impaired" else f"impaired:{record['action']}"
        self.counts[event] = self.counts.get(event, 0) + 1
        if self._file is not None:
            self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
            self._file.flush()


def read_events(path: str | Path) -> list[dict]:
    """The records of an event log (a torn last line, from a run that died mid-write, is skipped)."""
    events = []
    with open(path, encoding="utf-8") as f:
        for line in f:
            try:
                events.append(json.loads(line))
            except json.JSONDecodeError:
                break
    return events
