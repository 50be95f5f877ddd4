"""A fault plan applied to a live run, by its launcher.

A thread of the launcher keeps the plan's clock: game time from the start
command, and the events faults count from, as the launcher sees them on
the bus (the referee's state says when the flag was taken; a player's
truth says when it went). When a fault is due:

- process faults are real signals to the peer's process tree: SIGKILL,
  SIGTERM, SIGSTOP then SIGCONT, a kill and a fresh start that resumes
  from the peer's own log; CPU starvation moves the tree into a cgroup
  capped at a share of one core. A peer started by hand, whose process
  the launcher does not hold, is told as of a network fault, and kills,
  stops or pauses itself;
- network, clock and GPS faults are announced on the game's fault key
  (``FaultNotice``: which fault of the plan, from when until when, on the
  launcher's clock), and every peer applies what concerns it
  (``fault_effects``); on a kernel network the hub also drops or degrades
  the real packets of the peers cut off, so their sessions notice as they
  would in the field;
- a full disk: the run directory is a small tmpfs from the start, and the
  fault fills it.

Every fault is noted in the event log when it starts and ends (``fault``,
``fault-end``), as the simulated injector notes it, for the run checker.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
from pathlib import Path

from bearcat.bus import keys
from bearcat.bus.codec import encode
from bearcat.bus.messages import FaultNotice, GameState, Truth
from bearcat.scenarios.fault_effects import noted, sides
from bearcat.scenarios.faults import BY_ITSELF, GROUND, Fault, Restart

log = logging.getLogger(__name__)

TICK = 0.05  # s between looks at the plan
CGROUP_ROOTS = (Path("/sys/fs/cgroup/cpu"), Path("/sys/fs/cgroup"))  # cgroup v1's cpu controller, or v2
PERIOD_US = 100_000


class LiveFaults:
    """Applies ``plan`` to the peers of a live run.

    ``children`` maps each peer's name to its process (a restart puts the
    new one there); ``restart(name)`` starts a peer again, resuming;
    ``network`` is the run's kernel network (None on the shim); ``fill()``
    fills the run directory's disk; ``logs`` is where each peer's log is, in
    which the fault that kills a peer says so, as the peer cannot."""

    def __init__(
        self, plan: tuple[Fault, ...], *, game, session, record, lock, children, restart, network, logs, fill=None
    ):
        self.plan, self.game, self.session, self.record, self.lock = plan, game, session, record, lock
        self.children, self.restart, self.network, self.fill = children, restart, network, fill
        self.logs = Path(logs)
        self.happened: dict[str, float] = {}
        self.applied: list[dict] = []
        # peer -> (the fault that took it down, whether it comes back)
        self.out_of_play: dict[str, tuple[str, bool]] = {}
        self._due: list[tuple[int, Fault]] = list(enumerate(plan))
        self._ends: list[tuple[float, int, Fault]] = []
        self._cgroups: dict[int, Path] = {}
        self._paused: dict[int, list[int]] = {}
        self._returning: list[str] = []  # peers due to start again
        self._open_cuts: list[tuple[int, Fault]] = []  # partitions and outages that last until healed
        self._halt = threading.Event()
        self._thread = threading.Thread(target=self._run, name="faults", daemon=True)

    # ------------------------------------------------------------------ the launcher's calls

    def begin(self, t0: float) -> None:
        """The game started at Unix time ``t0``."""
        self.happened["start"] = t0
        self._thread.start()

    def saw(self, message, now: float) -> None:
        """A message the launcher saw: some mark the events faults count from."""
        if isinstance(message, GameState) and message.flag_holder is not None:
            self._happen("flag-taken", now)
        elif isinstance(message, Truth) and message.going:
            self._happen(f"{message.agent}.goes", now)

    def respawn(self) -> None:
        """Start again the peers whose restart is due. The launcher's own thread
        calls this: a child dies with the thread that started it (the
        parent-death signal follows the thread), and this one ends first."""
        while self._returning:
            name = self._returning.pop(0)
            self.children[name] = self.restart(name)
            self.out_of_play.pop(name, None)

    def close(self) -> None:
        """Undo what still holds: thaw the paused, free the starved, end every announced fault."""
        self._halt.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        for k in list(self._paused):
            self._thaw(k)
        for k in list(self._cgroups):
            self._free(k)
        if self.network is not None:
            self.network.heal()

    # ------------------------------------------------------------------ the plan's clock

    def _happen(self, name: str, now: float) -> None:
        with self.lock:
            if name not in self.happened:
                self.happened[name] = now
                self.record.note(now, "happened", name=name)

    def _run(self) -> None:
        while not self._halt.wait(TICK):
            now = time.time()
            for k, fault in list(self._due):
                origin = self.happened.get(fault.after)
                if origin is not None and now >= origin + fault.at:
                    self._due.remove((k, fault))
                    self._guarded(self._apply, k, fault, now)
            for end in sorted(e for e in self._ends if e[0] <= now):
                self._ends.remove(end)
                self._guarded(self._finish, end[1], end[2], now)

    def _guarded(self, action, k: int, fault: Fault, now: float) -> None:
        try:
            action(k, fault, now)
        except OSError as exc:
            log.error("fault[%d] (%s) could not be applied: %s", k, fault.kind, exc)
            with self.lock:
                self.record.note(now, "fault-failed", fault=k, kind=fault.kind, reason=str(exc)[:200])

    def _apply(self, k: int, fault: Fault, now: float) -> None:
        with self.lock:
            self.applied.append(noted(self.record, k, fault, now))
        if fault.kind in BY_ITSELF and not set(fault.peers()) & set(self.children):  # a peer started by hand
            self._announce(k, fault, now)
        else:
            getattr(self, "_" + fault.kind.replace("-", "_"))(k, fault, now)
        if fault.ends is not None:
            self._ends.append((now + fault.ends, k, fault))

    def _finish(self, k: int, fault: Fault, now: float) -> None:
        if fault.kind == "pause":
            self._thaw(k)
        elif fault.kind == "cpu":
            self._free(k)
        elif isinstance(fault, Restart):
            self._returning.append(fault.target)
        elif fault.kind in ("partition", "outage", "degrade") and self.network is not None:
            self.network.heal(fault.peers() if fault.kind == "degrade" else None)
        with self.lock:
            self.record.note(now, "fault-end", fault=k, kind=fault.kind)

    # ------------------------------------------------------------------ processes

    def _kill(self, k, fault, now) -> None:
        self.out_of_play[fault.target] = (f"fault[{k}] ({fault.describe()})", fault.kind == "restart")
        for pid in reversed(tree(self.children[fault.target].pid)):
            _signal(pid, signal.SIGKILL)
        self.children[fault.target].wait()
        with open(self.logs / f"{fault.target}.log", "a", encoding="utf-8") as log_file:
            log_file.write(f"peer {fault.target}: killed by fault[{k}] ({fault.describe()})\n")

    def _stop(self, k, fault, now) -> None:
        self.out_of_play[fault.target] = (f"fault[{k}] ({fault.describe()})", False)
        for pid in leaves(self.children[fault.target].pid):
            _signal(pid, signal.SIGTERM)

    _restart = _kill

    def _pause(self, k, fault, now) -> None:
        pids = tree(self.children[fault.target].pid)
        for pid in pids:
            _signal(pid, signal.SIGSTOP)
        self._paused[k] = pids

    def _thaw(self, k: int) -> None:
        for pid in self._paused.pop(k, []):
            _signal(pid, signal.SIGCONT)

    def _cpu(self, k, fault, now) -> None:
        root = next((r for r in CGROUP_ROOTS if (r / "cgroup.procs").exists() and os.access(r, os.W_OK)), None)
        if root is None:
            raise OSError("no writable cgroup cpu controller under /sys/fs/cgroup")
        group = root / f"bearcat-{os.getpid()}-{k}"
        group.mkdir(exist_ok=True)
        quota = max(1000, round(fault.share * PERIOD_US))
        if (group / "cpu.max").exists():
            (group / "cpu.max").write_text(f"{quota} {PERIOD_US}")
        else:
            (group / "cpu.cfs_period_us").write_text(str(PERIOD_US))
            (group / "cpu.cfs_quota_us").write_text(str(quota))
        for pid in tree(self.children[fault.target].pid):
            try:
                (group / "cgroup.procs").write_text(str(pid))
            except ProcessLookupError:
                pass
        self._cgroups[k] = group

    def _free(self, k: int) -> None:
        group = self._cgroups.pop(k)
        for pid in (group / "cgroup.procs").read_text().split():
            try:
                (group.parent / "cgroup.procs").write_text(pid)
            except ProcessLookupError:
                pass
        group.rmdir()

    def _disk_full(self, k, fault, now) -> None:
        self.fill()

    # ------------------------------------------------------------------ announced to the peers

    def _announce(self, k, fault, now) -> None:
        end = None if fault.ends is None else now + fault.ends
        if fault.kind == "partition" and end is None:
            self._open_cuts.append((k, fault))
        elif fault.kind == "heal":
            for cut, _ in self._open_cuts:
                with self.lock:
                    self.record.note(now, "fault-end", fault=cut, kind="partition")
            self._open_cuts.clear()
        notice = FaultNotice(fault=k, start=now, end=end)
        self.session.put(keys.fault(self.game), encode(notice))
        if self.network is not None and fault.kind in ("partition", "outage"):
            side, rest = sides(fault)
            home = side.get(GROUND, rest)
            self.network.cut([p for p in self.children if side.get(p, rest) != home])
        elif self.network is not None and fault.kind == "heal":
            self.network.heal()
        elif self.network is not None and fault.kind == "degrade":
            self.network.degrade([fault.target], fault.profile)

    _partition = _outage = _heal = _degrade = _clock = _gps = _announce


def tree(pid: int) -> list[int]:
    """``pid`` and its descendants, parents first."""
    children = _children()
    found, todo = [], [pid]
    while todo:
        p = todo.pop(0)
        found.append(p)
        todo.extend(children.get(p, []))
    return found


def leaves(pid: int) -> list[int]:
    """The processes of ``pid``'s tree that started none: the peer itself, under any wrapper."""
    children = _children()
    return [p for p in tree(pid) if not children.get(p)]


def _children() -> dict[int, list[int]]:
    """Every process's children, from ``/proc``."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            parent = int(stat.rpartition(")")[2].split()[1])
            children.setdefault(parent, []).append(int(entry))
    return children


def _signal(pid: int, sig: int) -> None:
    try:
        os.kill(pid, sig)
    except ProcessLookupError:
        pass
