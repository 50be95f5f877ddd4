"""A run that outlives its launcher: what ``bearcat run --resume RUN`` needs.

A launcher that dies (SIGKILL, a crashed laptop session, a closed
terminal) takes its peers with it, and each says so in its log on its way
out (``peers``). What the run recorded stays: every log is appended a line
at a time. Taking the run up again is a recovery command, as a database's
write-ahead log has one: the launcher is started again on the same run
directory with the settings it was launched with (``launch.json``,
written before any peer starts), on the same router port (so browser
phones and peers on other machines rejoin by themselves), with the same
certificates and the phones' same page tokens. The ground station resumes
from its log, the walkers where they stood, the logs carry on appended,
and the gap is an event of the run's log (``resumed``).

The game clock is the referee's and runs on the wall clock: in the field
the people keep walking while a laptop reboots, so the gap is game time,
as it is for a ground station its supervisor restarts. A fault plan is not
applied again: the faults it applied before the gap stay recorded.
"""

from __future__ import annotations

import os
from pathlib import Path

import msgspec

from bearcat.runtime import processes

LAUNCHED = "launch.json"


class ResumeError(ValueError):
    """A run that cannot be taken up; the text says why, in one sentence."""


class Launched(msgspec.Struct, frozen=True, kw_only=True):
    """How a run was launched, and by which process (``launcher``)."""

    scenario_ref: str
    seed: int
    netem: str
    transport: str
    network: str
    secure: bool
    certs: str | None  # a directory of the user's; None: the run's own authority, in RUN/certs
    phones: tuple[str, ...]
    joins: tuple[str, ...]
    page: tuple[str, int]
    provisional: bool
    listen: tuple[str, ...]
    port: int
    launchers: tuple[processes.Started, ...]  # the first, and each that took the run up again


def write_launched(out: Path, launched: Launched) -> None:
    """Keep how the run in ``out`` was launched, before anything starts; a
    run taken up again keeps it with its new launcher added, replaced whole
    (a rename), so a reader sees the old or the new, never half of one."""
    path = Path(out) / LAUNCHED
    temporary = path.with_name(f".{LAUNCHED}.{os.getpid()}")
    temporary.write_bytes(msgspec.json.format(msgspec.json.encode(launched)) + b"\n")
    temporary.replace(path)


def launcher_of(pid: int | None = None) -> processes.Started:
    """This process (or ``pid``), as the run records a process."""
    pid = os.getpid() if pid is None else pid
    return processes.Started("launcher", pid, processes.start_time(pid), processes.host())


def takes_up(out: Path) -> Launched:
    """How the run in ``out`` was launched, if it can be taken up: it has
    no outcome (it did not end), and neither its launcher nor any of its
    peers still runs."""
    out = Path(out)
    if not (out / "events.jsonl").exists():
        raise ResumeError(f"{out} is not a run directory: it has no events.jsonl")
    if (out / "outcome.json").exists():
        raise ResumeError(f"{out} ended already (it has its outcome.json): there is nothing to take up")
    try:
        launched = msgspec.json.decode((out / LAUNCHED).read_bytes(), type=Launched)
    except FileNotFoundError:
        raise ResumeError(
            f"{out} cannot be taken up: it has no {LAUNCHED} (it was launched before runs kept one)"
        ) from None
    except msgspec.DecodeError as exc:
        raise ResumeError(f"{out / LAUNCHED} does not read as a launch: {exc}") from None
    alive = [p for p in launched.launchers if processes.running(p)]
    if alive:
        raise ResumeError(f"{out} is still running: its launcher (process {alive[0].pid}) is alive")
    left = [p for p in processes.recorded(out) or [] if processes.running(p)]
    if left:
        raise ResumeError(f"{out} is still running: its peer {left[0].name} (process {left[0].pid}) is alive")
    return launched


def last_record(out: Path) -> float | None:
    """When the launcher's log of the run in ``out`` last recorded anything."""
    from bearcat.agents.ground_station.event_log import read_events

    return max((e["t"] for e in read_events(Path(out) / "events.jsonl") if "t" in e), default=None)
