"""Fault plans: what goes wrong in a run, and when.

A plan is data, like a scenario: ``[[fault]]`` tables in the scenario file
itself, or in a file of their own given with ``--faults``::

    [[fault]]
    kind = "pause"               # what goes wrong (the kinds below)
    target = "gs"                # the peer it happens to: gs, an agent or a UAV
    at = 10.0                    # s of game time ...
    after = "attacker.goes"      # ... counted from this event (default: the start)
    duration = 5.0               # s, for the kinds that last

    [[fault]]
    kind = "partition"
    groups = [["attacker"], ["gs", "defender"]]
    at = 20.0
    duration = 8.0               # or until a [[fault]] of kind "heal"

The kinds follow Jepsen's nemeses and Chaos Mesh's fault kinds: a peer's
process is killed (SIGKILL), stopped (SIGTERM), paused (SIGSTOP, then
SIGCONT), restarted; the network is partitioned and healed, one peer's
links go out or are degraded to another profile; a peer's clock jumps or
drifts; a phone's GPS jumps, freezes or is spoofed; the run directory's
disk fills; a peer is starved of CPU. Events a fault may count from:
``start``, ``flag-taken`` (the referee says the flag was taken) and
``AGENT.goes`` (that attacker commits to its run: a fake-out's go, a
go-no-go's go).

One sentence names a bad fault: ``plan.toml: fault[2].target: there is no
peer 'atacker'; the peers are gs, attacker, defender``. A fault a runtime
cannot apply is refused before the run, in one sentence too
(``refusal``).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import msgspec
from msgspec import Meta

from bearcat.bus.keys import GROUND
from bearcat.bus.messages import Name
from bearcat.netem.profiles import load_profiles
from bearcat.validation import Invalid, convert

GROUND_AGENTS = (GROUND, "referee", "uav-tasking")
"""The agents the ground station's process holds: the guidance service, the referee and the UAV tasking."""
LAUNCHER = "launcher"
"""The launcher's peer name: it sits on the ground station's side of every cut."""

GameTime = Annotated[float, Meta(ge=0.0, le=86400.0, extra={"unit": "s"})]
Lasting = Annotated[float, Meta(gt=0.0, le=86400.0, extra={"unit": "s"})]
Metres = Annotated[float, Meta(ge=-1e6, le=1e6, extra={"unit": "m"})]
Offset = Annotated[tuple[Metres, Metres], Meta(description="[east, north] in metres")]
if TYPE_CHECKING:
    ProfileName = str  # read from the profiles file: checked when a plan is read
else:
    ProfileName = Literal[tuple(load_profiles())]
Event = Annotated[str, Meta(min_length=1, max_length=80)]

EVENTS = ("start", "flag-taken")
"""Events a fault may count from, besides ``AGENT.goes``."""


class _Fault(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True, tag_field="kind"):
    at: GameTime = 0.0
    after: Event = "start"

    @property
    def kind(self) -> str:
        tag = self.__struct_config__.tag
        assert isinstance(tag, str)  # every kind of fault is tagged with its name
        return tag

    @property
    def ends(self) -> float | None:
        """Seconds from its start until it stops by itself; None: it does not."""
        return getattr(self, "duration", None)

    def peers(self) -> tuple[str, ...]:
        """The peers it names."""
        target = getattr(self, "target", None)
        return () if target is None else (target,)

    def describe(self) -> str:
        """One line for tables: the kind, its target and when."""
        who = ",".join(self.peers())
        when = f"{self.at:g} s" + ("" if self.after == "start" else f" after {self.after}")
        lasting = "" if self.ends is None else f" for {self.ends:g} s"
        return f"{self.kind} {who} at {when}{lasting}".replace("  ", " ")


class Kill(_Fault, tag="kill", kw_only=True, frozen=True):
    """The peer's process is killed (SIGKILL): it says no goodbye."""

    target: Name


class Stop(_Fault, tag="stop", kw_only=True, frozen=True):
    """The peer is asked to stop (SIGTERM) and does, cleanly."""

    target: Name


class Pause(_Fault, tag="pause", kw_only=True, frozen=True):
    """The peer's process is frozen (SIGSTOP) and thawed (SIGCONT) ``duration`` s later."""

    target: Name
    duration: Lasting


class Restart(_Fault, tag="restart", kw_only=True, frozen=True):
    """The peer is killed and started again ``duration`` s later; it resumes from what it recorded."""

    target: Name
    duration: Annotated[float, Meta(ge=0.0, le=3600.0, extra={"unit": "s"})] = 1.0


class Partition(_Fault, tag="partition", kw_only=True, frozen=True):
    """The peers are cut into ``groups``: nothing crosses from one to another.
    Peers no group names stay with the ground station. It lasts ``duration``
    s, or until a heal."""

    groups: Annotated[tuple[Annotated[tuple[Name, ...], Meta(min_length=1)], ...], Meta(min_length=1)]
    duration: Lasting | None = None

    def peers(self) -> tuple[str, ...]:
        return tuple(p for group in self.groups for p in group)

    def describe(self) -> str:
        cut = " | ".join(" ".join(group) for group in self.groups)
        return super().describe().replace(",".join(self.peers()), cut, 1)


class Heal(_Fault, tag="heal", kw_only=True, frozen=True):
    """Every partition in force ends."""


class Outage(_Fault, tag="outage", kw_only=True, frozen=True):
    """Every link to and from the peer is down for ``duration`` s."""

    target: Name
    duration: Lasting


class Degrade(_Fault, tag="degrade", kw_only=True, frozen=True):
    """The peer's links follow network profile ``profile`` for ``duration`` s."""

    target: Name
    profile: ProfileName
    duration: Lasting


class Clock(_Fault, tag="clock", kw_only=True, frozen=True):
    """The peer's clock jumps by ``offset`` s and then drifts by ``drift``
    s per s, for ``duration`` s or to the end. Namespaces share the kernel's
    clock, so this is the peer's own clock, not the host's."""

    target: Name
    offset: Annotated[float, Meta(ge=-86400.0, le=86400.0, extra={"unit": "s"})] = 0.0
    drift: Annotated[float, Meta(ge=-0.5, le=0.5, extra={"unit": "s/s"})] = 0.0
    duration: Lasting | None = None


class Gps(_Fault, tag="gps", kw_only=True, frozen=True):
    """The phone's fixes lie: ``jump`` adds ``offset``, ``freeze`` repeats the
    last fix, ``spoof`` reports ``position``; for ``duration`` s or to the end."""

    target: Name
    mode: Literal["jump", "freeze", "spoof"]
    offset: Offset = (0.0, 0.0)
    position: Offset | None = None
    duration: Lasting | None = None


class DiskFull(_Fault, tag="disk-full", kw_only=True, frozen=True):
    """The run directory's disk fills up (a tmpfs of ``size`` bytes holds the run)."""

    size: Annotated[int, Meta(ge=1 << 20, le=1 << 34, extra={"unit": "bytes"})] = 64 << 20


class Cpu(_Fault, tag="cpu", kw_only=True, frozen=True):
    """The peer gets only ``share`` of one core for ``duration`` s."""

    target: Name
    share: Annotated[float, Meta(gt=0.0, le=1.0)] = 0.1
    duration: Lasting


Fault = Kill | Stop | Pause | Restart | Partition | Heal | Outage | Degrade | Clock | Gps | DiskFull | Cpu
KINDS = tuple(kind.__struct_config__.tag for kind in Fault.__args__)
PROCESS_KINDS = ("kill", "stop", "pause", "restart", "cpu")

#: Process faults a peer started by hand cannot apply to itself, and why. No
#: launcher holds its process, so it applies the others (``BY_ITSELF``) on
#: the launcher's notice; these are refused before the run.
NOT_BY_ITSELF = {
    "restart": "no launcher holds its process to start it again",
    "cpu": "starving it takes a cgroup on its own machine, which the launcher cannot reach",
}
BY_ITSELF = tuple(kind for kind in PROCESS_KINDS if kind not in NOT_BY_ITSELF)

#: What each runtime cannot do, and why: a fault of these kinds is refused before the run.
CANNOT = {
    "simulate": {
        "disk-full": "simulate keeps its run directory on the disk it was given; run it live to fill a disk",
        "cpu": "in virtual time every agent gets all the time it needs; run it live to starve a peer",
    },
    "live": {},
}


class PlanFile(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    fault: tuple[Fault, ...] = ()


class FaultError(ValueError):
    """A fault plan that cannot be run; the text names the file and the fault."""


def parse_faults(data: object, *, at: str = "fault") -> tuple[Fault, ...]:
    """The faults of a list of ``[[fault]]`` tables (an ``Invalid`` names a bad key)."""
    return convert(data, tuple[Fault, ...], at=at)


def load_faults(path: str | Path, scenario) -> tuple[Fault, ...]:
    """The faults in plan file ``path``, checked against ``scenario``."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FaultError(f"there is no fault plan {str(path)!r}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise FaultError(f"{path} cannot be read: {exc}") from None
    return parse_plan(text, scenario, source=str(path))


def parse_plan(text: str, scenario, *, source: str) -> tuple[Fault, ...]:
    """The faults in the text of a plan file from ``source``, checked against ``scenario``."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FaultError(f"{source} is not valid TOML: {exc}") from None
    try:
        plan = convert(data, PlanFile).fault
        check_faults(plan, scenario.agents, scenario.uavs, scenario.committing)
    except Invalid as exc:
        raise FaultError(f"{source}: {exc}") from None
    return plan


def write_faults(path: str | Path, faults) -> None:
    """Write ``faults`` as a plan file (what a run keeps, and hands its peers)."""
    import tomli_w

    tables = [{k: v for k, v in msgspec.to_builtins(f).items() if v is not None} for f in faults]
    Path(path).write_text(tomli_w.dumps({"fault": tables}), encoding="utf-8")


def check_faults(faults, agents, uavs, committing) -> None:
    """What needs the scenario's ``agents`` and ``uavs``: the peers and events
    a plan names (``Invalid`` for the first wrong one). ``committing`` are
    the agents whose behaviour commits to a run, so that ``AGENT.goes`` happens."""
    peers = [GROUND, *(a.id for a in agents), *(u.id for u in uavs)]
    behaviours = {a.id: a.behaviour for a in agents}
    for k, fault in enumerate(faults):
        for name in fault.peers():
            if name not in peers:
                key = "groups" if isinstance(fault, Partition) else "target"
                raise Invalid(f"fault[{k}].{key}", f"there is no peer {name!r}; the peers are {', '.join(peers)}")
        if isinstance(fault, Partition):
            named = fault.peers()
            twice = sorted({p for p in named if named.count(p) > 1})
            if twice:
                raise Invalid(f"fault[{k}].groups", f"peer {twice[0]!r} is in two groups")
        if isinstance(fault, Gps):
            if fault.target not in behaviours:
                phones = ", ".join(behaviours)
                raise Invalid(f"fault[{k}].target", f"{fault.target!r} carries no phone; the phones are {phones}'s")
            if fault.mode == "spoof" and fault.position is None:
                raise Invalid(f"fault[{k}].position", "a spoofed fix needs the [east, north] it reports")
        _check_event(fault.after, behaviours, frozenset(committing), f"fault[{k}].after")


def _check_event(event: str, behaviours: dict[str, str], committing: frozenset[str], where: str) -> None:
    if event in EVENTS:
        return
    agent, dot, what = event.rpartition(".")
    if not dot or what != "goes":
        raise Invalid(where, f"{event!r} is not an event; the events are {', '.join(EVENTS)} and AGENT.goes")
    if agent not in behaviours:
        raise Invalid(where, f"there is no agent {agent!r}; the agents are {', '.join(behaviours)}")
    if agent not in committing:
        raise Invalid(
            where,
            f"agent {agent} never goes: its behaviour {behaviours[agent]} does not commit to a run "
            "(it declares no 'commits' trait)",
        )


def peers_of(scenario) -> list[str]:
    """The peers of a scenario's live run, by the names faults use."""
    return [GROUND, *(a.id for a in scenario.agents), *(u.id for u in scenario.uavs)]


def refusal(faults, runtime: str) -> str | None:
    """Why ``runtime`` ("simulate" or "live") cannot apply ``faults``, or None."""
    for k, fault in enumerate(faults):
        why = CANNOT[runtime].get(fault.kind)
        if why is not None:
            return f"fault[{k}] ({fault.kind}) cannot be applied by {runtime}: {why}"
    return None
