"""A peer on another machine hands its log to the launcher at the end.

The launcher judges a run from its directory, but a peer started elsewhere
(a drone's companion computer, a second laptop) writes its event log on its
own machine. On its way out such a peer (``--hand-in``) serves the log on
its key (``keys.log_query``) from a session of its own, for as long as the
scenario's lease, and leaves once it has been asked and a moment has
passed without another ask. The launcher asks each of them in turn, for
a lease at most, and keeps what comes back as ``peers/NAME.jsonl``, beside
a seal (``peers/NAME.seal.json``): who the answer came from, proven by its
signature on a run with certificates, and the log's SHA-256, which the
run checker holds the file to. The peer keeps its own copy.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
import time
from pathlib import Path

import msgspec

from bearcat.bus import keys

QUIET = 1.0  # s a peer that handed in its log waits for another ask before it leaves
ASK = 1.0  # s the launcher waits for each answer


class Seal(msgspec.Struct, frozen=True, kw_only=True):
    """What the launcher knew of a log it was handed: the peer it asked,
    who answered (``proven`` when the answer's signature showed it), the
    log's size and SHA-256, and when (Unix time)."""

    peer: str
    sender: str
    proven: bool
    bytes: int
    sha256: str
    t: float


def seal_path(run: Path, peer: str) -> Path:
    return Path(run) / "peers" / f"{peer}.seal.json"


def serve_log(session, game: str, peer: str, log: Path, lease: float) -> bool:
    """Serve ``log`` on ``session`` until it has been asked for and ``QUIET``
    s have passed without another ask, or ``lease`` s without any; whether
    it was asked for."""
    asked = threading.Event()
    last = [0.0]

    def answer() -> bytes:
        last[0] = time.monotonic()
        asked.set()
        return log.read_bytes()

    session.serve(keys.log_query(game, peer), answer)
    if not asked.wait(lease):
        return False
    while time.monotonic() - last[0] < QUIET:
        time.sleep(QUIET / 10)
    return True


def take_log(session, game: str, peer: str, run: Path, lease: float) -> Seal | None:
    """Ask peer ``peer`` for its log, for ``lease`` s at most, and keep it
    in ``run``'s ``peers`` with its seal; the seal, or None if no answer
    came. A log already there is never overwritten: the peer wrote it."""
    path = Path(run) / "peers" / f"{peer}.jsonl"
    end = time.monotonic() + lease
    while time.monotonic() < end:
        answer = session.ask(keys.log_query(game, peer), timeout=ASK)
        if answer is None:
            continue
        payload, sender = answer
        seal = Seal(
            peer=peer,
            sender=sender,
            proven=session.credentials is not None,
            bytes=len(payload),
            sha256=hashlib.sha256(payload).hexdigest(),
            t=time.time(),
        )
        _write_new(path, payload)
        _write_new(seal_path(run, peer), json.dumps(msgspec.to_builtins(seal), indent=2).encode() + b"\n")
        return seal
    return None


def broken_seal(run: Path, peer: str) -> str | None:
    """Why ``peer``'s handed-in log no longer matches its seal, or None if it does."""
    try:
        seal = msgspec.json.decode(seal_path(run, peer).read_bytes(), type=Seal)
    except (OSError, msgspec.DecodeError, msgspec.ValidationError) as exc:
        return f"peers/{peer}.seal.json cannot be read ({exc})"
    try:
        data = (Path(run) / "peers" / f"{peer}.jsonl").read_bytes()
    except OSError:
        return f"peers/{peer}.jsonl, which {peer} handed in, is gone"
    if hashlib.sha256(data).hexdigest() != seal.sha256:
        return f"peers/{peer}.jsonl is not the log {seal.sender} handed in: its SHA-256 differs from its seal's"
    return None


def _write_new(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path``, which must not exist yet, whole or not at all."""
    partial = path.with_name(path.name + ".partial")
    partial.write_bytes(data)
    try:
        os.link(partial, path)  # fails if ``path`` exists: nothing recorded is overwritten
    finally:
        partial.unlink()
