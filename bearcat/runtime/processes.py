"""The processes a live run started, recorded in its run directory so that
the run checker tells them from every other process on the host.

Neither a process's number nor its command line names it: the kernel hands
a number on once its process is gone, and a ``timeout`` or a script that
wraps ``bearcat check RUN`` names the run directory as well as any peer.
A process is its number and its start time (clock ticks after boot, field
22 of ``/proc/PID/stat``), a pair no later process shares; and the pair
names a process only under the boot, and in the PID namespace, it was read
in (``host``).

The launcher creates ``processes.jsonl`` before it starts anything, then
appends a line as each process starts (a peer, a peer started again, a
UAV's vehicle, a kernel network's hub), each with one system call and never
rewriting one, so what is recorded stays there however the launcher ends.
A run directory without the file was written before runs recorded them.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import msgspec

log = logging.getLogger(__name__)

PROCESSES = "processes.jsonl"


class Started(msgspec.Struct, frozen=True):
    """Process ``pid`` the run started as ``name``, at ``start`` ticks after boot, on ``host``."""

    name: str
    pid: int
    start: int
    host: str


def begin(directory: Path) -> None:
    """Say that the run in ``directory`` records the processes it starts (none yet)."""
    (Path(directory) / PROCESSES).touch()


def record(directory: Path, name: str, pid: int) -> None:
    """Append process ``pid``, started as ``name`` and not yet waited for, to the run's record.
    A line the disk refuses is cut back and logged, not raised: the process runs
    either way, and the launcher must still supervise and stop it."""
    path = Path(directory) / PROCESSES
    line = msgspec.json.encode(Started(name, pid, start_time(pid), host())) + b"\n"
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    except OSError as exc:
        log.error("%s: process %d (%s) could not be recorded: %s", path, pid, name, exc)
        return
    try:
        size = os.fstat(fd).st_size
        try:
            written = os.write(fd, line)
            if written < len(line):
                raise OSError(f"only {written} of {len(line)} bytes written")
        except OSError as exc:
            os.ftruncate(fd, size)
            log.error("%s: process %d (%s) could not be recorded: %s", path, pid, name, exc)
    finally:
        os.close(fd)


def recorded(directory: Path) -> list[Started] | None:
    """The processes the run in ``directory`` recorded starting; None if it kept
    no record. A line that does not read is a ``ValueError`` naming it."""
    path = Path(directory) / PROCESSES
    try:
        lines = path.read_bytes().splitlines()
    except FileNotFoundError:
        return None
    decode = msgspec.json.Decoder(Started).decode
    started = []
    for n, line in enumerate(lines, 1):
        try:
            started.append(decode(line))
        except msgspec.DecodeError:
            raise ValueError(f"{PROCESSES} line {n} does not read as a process") from None
    return started


def running(process: Started) -> bool:
    """Whether ``process`` still runs here: its number names a live process started at its time."""
    try:
        fields = _stat(process.pid)
    except OSError:
        return False
    return fields[0] not in ("Z", "X") and int(fields[19]) == process.start  # a zombie has ended


def start_time(pid: int) -> int:
    """When process ``pid`` started, in clock ticks after boot."""
    return int(_stat(pid)[19])


def host() -> str:
    """The boot and the PID namespace this process reads process numbers in."""
    boot = Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    return f"{boot} {os.readlink('/proc/self/ns/pid')}"


def _stat(pid: int) -> list[str]:
    """Fields 3 on of ``/proc/PID/stat`` (field 2, the name in parentheses, may hold anything)."""
    text = Path(f"/proc/{pid}/stat").read_text()
    return text[text.rindex(")") + 2 :].split()
