"""The run checker: which invariants a run directory shows held, with the evidence.

It reads only the directory (the event logs, the peers' logs, the outcome,
the scenario the run played), so it judges runs it did not start, simulated
or live, as Jepsen's checkers judge a history. Each invariant is held,
broken, or does not apply to the run (``None``), with one line of evidence:

- ``logs``: every event log parses to its last line, the outcome is there
  (or the peers saw their launcher die, and none took the run up: then
  ``verdict`` says the run ended without one, and when),
  and every peer's log says how the peer ended; a log a peer on another
  machine handed in matches the SHA-256 of its seal;
- ``reliable``: every reliable message (state, control, UAV tasks) reached
  each peer that listens to its key, unless a fault had cut that peer off,
  or it was sent before the peer first heard anything or after it stopped;
- ``verdict``: the referee's verdict agrees with the truth track, and a
  game ended by a gone player names a peer a fault hit;
- ``detection``: a killed or stopped peer seen gone within ``KILL_SEEN`` s;
  a pause, outage or partition that outlasted the lease seen within the
  lease and ``SLACK`` s, and the peer back within ``REJOIN`` s of its end;
  a player cut off gets guidance again within ``REJOIN`` s of the heal;
- ``failsafe``: a UAV whose ground station vanished for longer than its
  link timeout applied its failsafe
  within its ``link_timeout`` after it vanished;
- ``supervision``: each peer that died when no fault plan asked for it
  was started again within its backoff and ``RESTART_SLACK`` s, as the
  scenario's ``[supervision]`` says, and was back on the bus within
  ``REJOIN`` s, or the run gave it up and says why; and the game still
  ended with a verdict (``verdict`` judges it against the truth);
- ``plugins``: every fault of a plug-in (``agents.guard``: it raised,
  answered what its protocol does not allow, or overran its budget) left
  its peer going: the peer sent on after it (a walker its truth, the
  ground station its state and UAV tasks), or the game ended within
  ``IN_FLIGHT`` s of it; and the game ended with a verdict (not judged
  where the outcome says it ended but the record lost its end, nor where
  the run has no verdict because a planned fault or supervision stopped
  it, as ``verdict`` accepts);
- ``leftovers``: no process the run started still runs, and a kernel run
  left neither its link nor its route in the host's namespace. The run
  names its own (``runtime.processes``, ``endpoint.json``): a process is
  its number and start time, a link its name and interface number, so
  neither a script that wraps the checker nor a later run's process, link
  or route of the same number or name is counted. A run that recorded no
  processes (from before runs did), or whose processes ran under another
  boot or PID namespace than the checker's, cannot be judged here.
"""

from __future__ import annotations

import itertools
import json
import math
import subprocess
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import msgspec
import numpy as np
import shapely

from bearcat.bus import keys
from bearcat.bus.errors import BusError
from bearcat.runtime import processes
from bearcat.runtime.hand_in import broken_seal
from bearcat.runtime.run_directory import SCENARIO
from bearcat.scenarios.faults import GROUND, GROUND_AGENTS, LAUNCHER

KILL_SEEN = 2.0  # s: a killed peer's TCP connection closes at once
SLACK = 2.0  # s past the lease for a silent peer to be declared gone
REJOIN = 10.0  # s for a peer to be seen again after its fault ends
RELIABLE_KINDS = ("state", "control", "task")
IN_FLIGHT = 2.0  # s before its receiver's last record a message must have arrived by
WINDOW = 1.0  # s of truth before the verdict in which a capture must show
ENDINGS = ("peer ", "vehicle ")
RESTART_SLACK = 2.0  # s from a restart's due time to its process being started
INVARIANTS = ("logs", "reliable", "verdict", "detection", "supervision", "failsafe", "plugins", "leftovers")
JUDGED = ("did", "plugin", "fault", "fault-end", "gone", "alive", "died", "restarted", "launcher-died", "resumed")
"""The events besides what was sent and received that an invariant reads."""
DETECTABLE = ("kill", "stop", "restart", "pause", "partition", "outage")


@dataclass(frozen=True)
class Finding:
    """One invariant: ``held`` True, False, or None where it does not apply."""

    name: str
    held: bool | None
    evidence: str


def check_run(directory: str | Path | Run) -> list[Finding]:
    """Every invariant of the run in ``directory`` (or of a ``Run`` read already)."""
    run = directory if isinstance(directory, Run) else Run(Path(directory))
    return [
        _logs(run),
        _reliable(run),
        _verdict(run),
        _detection(run),
        _supervision(run),
        _failsafe(run),
        _plugins(run),
        _leftovers(run),
    ]


class Run:
    """What a run directory recorded that the invariants judge, read once.

    A long run's logs hold gigabytes (fifty phones at 10 Hz, each answered
    with the positions of all fifty): only the events an invariant reads are
    kept, and of what a receiver got only the reliable kinds and guidance,
    with the span over which each receiver recorded anything."""

    def __init__(self, directory: Path) -> None:
        if not (directory / "events.jsonl").exists():
            raise FileNotFoundError(f"{directory} is not a run directory: it has no events.jsonl")
        self.directory = directory
        self.torn: dict[str, int] = {}  # log -> line number of its first unreadable line
        self.listening: dict[str | None, tuple[float, float]] = {}  # receiver -> first and last time it received
        self.events = self._read(directory / "events.jsonl")
        self.peer_logs = {p.stem: self._read(p) for p in sorted((directory / "peers").glob("*.jsonl"))}
        self.outcome = self._outcome()
        self.unreadable: str | None = None  # why scenario.toml could not be read here, if it could not
        self.scenario = self._scenario()
        self.live = (directory / "peers").is_dir()
        self.kernel = (directory / "network.json").exists()
        self.faults = [e for e in self.events if e["event"] == "fault"]
        self.ended = {e["fault"]: e["t"] for e in self.events if e["event"] == "fault-end"}
        self.seen = [e for e in self.events if e["event"] in ("gone", "alive")]
        self.deaths = [e for e in self.events if e["event"] == "died"]
        self.restarts = [e for e in self.events if e["event"] == "restarted"]
        # When each launcher that took the run up found it last recorded, and took it up.
        self.gaps = [(e["since"] or e["t"], e["t"]) for e in self.events if e["event"] == "resumed"]
        self._records = [e for log in self.peer_logs.values() for e in log] if self.peer_logs else self.events
        orphaned = [e["t"] for e in self._records if e["event"] == "launcher-died"]
        self.launcher_died: float | None = min(orphaned, default=None)  # when its peers first saw their launcher die

    def records(self) -> list[dict]:
        """What the peers sent and received: their own logs in a live run, the one log in a simulated one."""
        return self._records

    def _read(self, path: Path) -> list[dict]:
        events = []
        decode = msgspec.json.Decoder().decode
        with open(path, "rb") as f:
            for n, line in enumerate(f, 1):
                try:
                    event = decode(line)
                except msgspec.DecodeError:
                    event = None
                if not isinstance(event, dict) or "event" not in event:
                    self.torn.setdefault(str(path.relative_to(self.directory)), n)
                elif self._judged(event):
                    events.append(event)
        return events

    def _judged(self, e: dict) -> bool:
        """Whether an invariant reads ``e``; notes the span of what each receiver got."""
        what = e["event"]
        if what == "received":
            receiver, t = e.get("receiver"), e.get("t", 0.0)
            first, last = self.listening.get(receiver, (t, t))
            self.listening[receiver] = (min(first, t), max(last, t))
            return _kind(e.get("key", "")) in (*RELIABLE_KINDS, "guidance")
        if what == "sent":
            return _kind(e.get("key", "")) in (*RELIABLE_KINDS, "truth")
        return what in (
            "did",
            "plugin",
            "fault",
            "fault-end",
            "gone",
            "alive",
            "died",
            "restarted",
            "launcher-died",
            "resumed",
        )

    def _outcome(self) -> dict | None:
        try:
            return json.loads((self.directory / "outcome.json").read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            return None

    def _scenario(self):
        from bearcat.scenarios.schema import ScenarioError, parse_scenario

        path = self.directory / SCENARIO
        if not path.exists():
            return None
        try:
            return parse_scenario(path.read_text(encoding="utf-8"), source=str(path))
        except ScenarioError as exc:  # a plug-in it names that this environment cannot import, say
            self.unreadable = str(exc)
            return None


# ---------------------------------------------------------------- the invariants


def _logs(run: Run) -> Finding:
    problems = [f"{name} is torn at line {n}" for name, n in run.torn.items()]
    if run.outcome is None and run.launcher_died is None:
        problems.append("outcome.json is missing or unreadable")
    for log in sorted((run.directory / "peers").glob("*.log")):
        lines = [line for line in log.read_text(errors="replace").splitlines() if line.strip()]
        if not lines or not lines[-1].startswith(ENDINGS):
            last = lines[-1][:80] if lines else "nothing"
            problems.append(f"peers/{log.name} does not say how the peer ended (its last line: {last!r})")
        elif any(line.startswith("Traceback") for line in lines):
            problems.append(f"peers/{log.name} holds a traceback")
    for seal in sorted((run.directory / "peers").glob("*.seal.json")):
        broken = broken_seal(run.directory, seal.name.removesuffix(".seal.json"))
        if broken is not None:
            problems.append(broken)
    if problems:
        return Finding("logs", False, "; ".join(problems))
    logs = 1 + len(run.peer_logs)
    if run.outcome is None:
        return Finding("logs", True, f"{logs} event log(s) parse to the last line; {_launcher_died(run)}")
    return Finding("logs", True, f"{logs} event log(s) parse to the last line; the outcome is there")


def _reliable(run: Run) -> Finding:
    sent: dict[tuple[str, str], list[tuple[float, int]]] = {}
    received: dict[tuple[str, str, str], set[int]] = {}
    for e in run.records():
        if e["event"] == "sent" and _kind(e["key"]) in RELIABLE_KINDS:
            sent.setdefault((e["sender"], e["key"]), []).append((e["t"], e["message"].get("seq", 0)))
        elif e["event"] == "received" and _kind(e["key"]) in RELIABLE_KINDS:
            received.setdefault((e["sender"], e["receiver"], e["key"]), set()).add(e["seq"])
    delivered = excused = 0
    missing = []
    for (sender, receiver, key), seqs in received.items():
        first, last = run.listening.get(receiver, (math.inf, -math.inf))
        for t, seq in sent.get((sender, key), []):
            if t > last - IN_FLIGHT or t < first:
                continue  # in flight when the receiver stopped recording, or sent before it listened
            if seq in seqs:
                delivered += 1
            elif _cut_off(run, t, sender, receiver):
                excused += 1
            else:
                missing.append(f"{key.rsplit('/', 1)[-1]} #{seq} from {sender} to {receiver} at {t:.1f}")
    if missing:
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        return Finding("reliable", False, f"never delivered: {'; '.join(missing[:3])}{more}")
    if delivered == 0:
        return Finding("reliable", None, "no reliable message was sent to a peer that recorded it")
    return Finding("reliable", True, f"{delivered} delivered; {excused} lost to faults that cut their peer off")


def _verdict(run: Run) -> Finding:
    if run.unreadable is not None:
        return Finding("verdict", None, f"the scenario cannot be read here to judge it by: {run.unreadable}")
    if run.outcome is None and run.launcher_died is not None:
        return Finding("verdict", None, f"ended without a verdict: {_launcher_died(run)}")
    if run.outcome is None or run.scenario is None:
        return Finding("verdict", None, "no outcome or no scenario.toml to judge it by")
    reason, winner = run.outcome.get("reason", ""), run.outcome.get("winner")
    ended = [e for e in run.events if e["event"] == "sent" and _kind(e["key"]) == "state"]
    final = next((e["message"] for e in reversed(ended) if e["message"]["phase"] == "ended"), None)
    if final is None:
        if _stopped_for_a_reason(run):
            return Finding("verdict", True, f"the run ended without a verdict, and says why: {reason}")
        return Finding("verdict", None, f"the game never ended ({reason})")
    if final.get("judged_on") != "truth":
        return Finding("verdict", None, "judged on fixes: there is no truth to check against")
    reason, winner, t_end = final["reason"], final["winner"], final["t"]
    track = _truth(run, t_end)
    # A live referee hears the truth over the network, a sample earlier or
    # later than the launcher logged it: grant each agent its longest step.
    slack = {a: _longest_step(points) if run.live else 0.0 for a, points in track.items()}
    s = run.scenario
    if " is gone" in reason:
        gone = reason.split(" is gone")[0].split()[-1]
        fault = next((f for f in reversed(run.faults) if gone in f.get("peers", []) and f["t"] <= t_end), None)
        death = next((e for e in run.deaths if e["peer"] == gone and not e["restart"]), None)
        if fault is None and death is not None:
            return Finding("verdict", True, f"{reason}: it died with code {death['code']} and {death['why']}")
        if fault is None:
            return Finding("verdict", False, f"{reason}, but no fault hit {gone}")
        return Finding("verdict", True, f"{reason}: ended by fault[{fault['fault']}] ({fault['describe']})")
    contest = _contest(s)
    if "captured" in reason:
        pairs = [(r, c) for r in contest.runners for c in contest.chasers if r in track and c in track]
        if not pairs:
            return Finding("verdict", False, f"{reason}, but the truth has no track of runner and chaser")
        r, c = min(pairs, key=lambda pair: _closest(track[pair[0]], track[pair[1]]))
        closest, allowed = _closest(track[r], track[c]), slack[r] + slack[c]
        ok = closest <= contest.capture_radius + allowed + 0.05
        granted = f", plus {allowed:.2f} m for one truth step of each" if allowed else ""
        return Finding(
            "verdict",
            ok,
            f"{reason}: the truth brings {r} and {c} within {closest:.2f} m "
            f"in the last {WINDOW:g} s (capture radius {contest.capture_radius:g} m{granted})",
        )
    regions = dict((*contest.targets, *contest.forbidden))
    if "returned the flag" in reason or "reached the" in reason or "entered the" in reason:
        agent = reason.split()[0]
        region = "home" if "returned the flag" in reason else reason.split(" the ")[-1].split()[0]
        shape, where = regions.get(region), track.get(agent)
        if shape is None or where is None:
            return Finding("verdict", None, f"{reason}: no truth of {agent} or no region {region}")
        inside = shape.distance(shapely.Point(where[-1][1])) <= slack[agent] + 0.05
        return Finding("verdict", inside, f"{reason}: the truth puts {agent} {'in' if inside else 'outside'} {region}")
    if "time limit" in reason:
        ok = final["elapsed"] >= s.time_limit - 0.2
        return Finding("verdict", ok, f"{reason}: {final['elapsed']:.1f} s of play, winner {winner}")
    return Finding("verdict", None, f"the game ended with {reason!r}, which the truth cannot judge")


def _detection(run: Run) -> Finding:
    if not run.faults:
        return Finding("detection", None, "no fault in this run")
    lease = run.scenario.lease if run.scenario is not None else 10.0
    said, broken = [], []
    for fault in run.faults:
        kind, t, peers = fault["kind"], fault["t"], fault.get("peers", [])
        if kind in ("kill", "stop", "restart") and peers:
            seen = _first(run, peers[0], "gone", t)
            if seen is None or seen - t > KILL_SEEN:
                broken.append(f"{kind} {peers[0]} at {t:.1f} s not seen gone within {KILL_SEEN:g} s")
            else:
                said.append(f"{kind} {peers[0]} seen gone after {seen - t:.2f} s")
        lasted = _lasted(run, fault)
        on_shim = kind in ("outage", "partition") and run.live and not run.kernel
        if on_shim:
            said.append(f"{kind} on the shim: its messages were cut, but no session could notice")
        elif kind in ("pause", "outage", "partition") and lasted is not None and lasted >= lease:
            watched = [p for p in peers if p != GROUND] or peers
            seen = _first(run, watched[0], "gone", t)
            if seen is None or seen - t > lease + SLACK:
                broken.append(f"{kind} {watched[0]} at {t:.1f} s not seen gone within the lease ({lease:g} s)")
            else:
                said.append(f"{kind} {watched[0]} seen gone after {seen - t:.1f} s (lease {lease:g} s)")
        end = run.ended.get(fault["fault"])
        if kind in ("pause", "outage", "partition", "restart") and end is not None and peers:
            watched = [p for p in peers if p != GROUND] or peers
            game_over = _game_end(run)
            gone = _first(run, watched[0], "gone", t)
            was_gone = gone is not None and gone <= end + SLACK
            back = _first(run, watched[0], "alive", end)
            if on_shim:
                pass
            elif was_gone and back is None and (game_over is None or game_over > end + REJOIN):
                broken.append(f"{watched[0]} not back within {REJOIN:g} s of the end of its {kind}")
            elif was_gone and back is not None:
                said.append(f"{watched[0]} back {back - end:.1f} s after its {kind} ended")
            if kind in ("outage", "partition"):
                fresh = _guided(run, watched, end)
                guided = [p for p in watched if _guided(run, [p], -math.inf) is not None]
                if fresh is not None and fresh - end <= REJOIN:
                    said.append(f"guided again {fresh - end:.1f} s after the heal")
                elif guided and (game_over is None or game_over > end + REJOIN):
                    broken.append(f"{guided[0]} got no guidance within {REJOIN:g} s of the heal")
    if broken:
        return Finding("detection", False, "; ".join(broken))
    return Finding("detection", True, "; ".join(said) or "no fault needed detecting")


def _supervision(run: Run) -> Finding:
    if not run.deaths:
        return Finding("supervision", None, "no peer died when no fault plan asked for it")
    said, broken = [], []
    for k, death in enumerate(run.deaths):
        peer, t = death["peer"], death["t"]
        if death["gives_up"]:
            if run.outcome is None or run.outcome.get("reason") != death["why"]:
                broken.append(f"the run gave {peer} up but its outcome does not say so")
            else:
                said.append(f"{peer} given up: {death['why']}")
            continue
        if not death["restart"]:
            said.append(f"{peer} died with code {death['code']}, not restarted: {death['why']}")
            continue
        # Its next life is judged until it dies again or the run ends.
        again = min((e["t"] for e in run.deaths[k + 1 :] if e["peer"] == peer), default=math.inf)
        then = min(again, _run_end(run))
        restarted = next((e["t"] for e in run.restarts if e["peer"] == peer and e["t"] >= t), None)
        due = t + death["wait"]
        if restarted is None:
            if then > due + RESTART_SLACK:
                broken.append(f"{peer} died and was not started again within {death['wait']:g} s")
            continue
        if restarted - due > RESTART_SLACK:
            broken.append(f"{peer} started again {restarted - t:.1f} s after its death, past its backoff")
            continue
        back = _first(run, peer, "alive", restarted)
        if (back is None or back > then) and then > restarted + REJOIN:
            broken.append(f"{peer}, started again {restarted - t:.1f} s after its death, not back within {REJOIN:g} s")
            continue
        first = "it died again" if again <= then else "the run ended"
        when = f"and {first} before it was back" if back is None or back > then else f"back {back - restarted:.1f} s on"
        said.append(f"{peer} died (code {death['code']}), started again {restarted - t:.1f} s later, {when}")
    if run.outcome is None or (not run.outcome.get("ended") and not any(d["gives_up"] for d in run.deaths)):
        reason = "no outcome" if run.outcome is None else run.outcome.get("reason")
        broken.append(f"the game ended without a verdict ({reason})")
    if broken:
        return Finding("supervision", False, "; ".join(broken))
    return Finding("supervision", True, "; ".join(said))


def _failsafe(run: Run) -> Finding:
    if run.scenario is None or not run.scenario.uavs:
        return Finding("failsafe", None, "no UAV in this run")
    findings = []
    for uav in run.scenario.uavs:
        # A loss shorter than the link timeout is over before a failsafe is due.
        lost = next((t for t, back in _ground_losses(run, uav.id) if back - t >= uav.link_timeout), None)
        if lost is None:
            continue
        acted = next(  # a failsafe applied before the loss (a slow start, an earlier gap) answers another
            (
                e
                for e in run.records()
                if e["event"] == "did" and e["agent"] == uav.id and "failsafe" in e["what"] and e["at"] >= lost
            ),
            None,
        )
        if acted is None or acted["at"] - lost > uav.link_timeout + 0.5:
            return Finding("failsafe", False, f"UAV {uav.id} lost its ground station at {lost:.1f} s and did nothing")
        findings.append(f"{uav.id}: {acted['what']} after {acted['at'] - lost:.1f} s")
    if not findings:
        return Finding("failsafe", None, "no UAV lost its ground station for longer than its link timeout")
    return Finding("failsafe", True, "; ".join(findings))


def _plugins(run: Run) -> Finding:
    faults = [e for e in run.records() if e["event"] == "plugin"]
    if not faults:
        return Finding("plugins", True, "no plug-in failed")
    told = Counter((e["agent"], e["plugin"], e["fault"]) for e in faults)
    said = "; ".join(
        f"{agent}'s {plugin} {fault} {n} time{'s' * (n > 1)}" for (agent, plugin, fault), n in told.items()
    )
    first = f"{faults[0]['agent']}: plug-in {faults[0]['plugin']} {faults[0]['detail']}"
    end = _game_end(run)
    if end is None and run.outcome is not None and run.outcome.get("ended"):
        why = "the record lacks the game's end (lines a full disk refused, say)"
        return Finding("plugins", None, f"{said}; {why}, so whether each peer went on cannot be judged")
    if end is None and _stopped_for_a_reason(run):
        assert run.outcome is not None
        why = f"the run ended without a verdict because {run.outcome.get('reason')}"
        return Finding("plugins", None, f"{said}; {why}, so whether the game went on to one cannot be judged")
    if end is None:
        return Finding("plugins", False, f"{said}, and the game ended without a verdict (first: {first})")
    last_fault: dict[str, float] = {}
    for e in faults:
        last_fault[e["peer"]] = max(last_fault.get(e["peer"], e["at"]), e["at"])
    sent: dict[str, float] = {}
    for e in run.records():
        if e["event"] == "sent":
            sent[e["sender"]] = max(sent.get(e["sender"], e["t"]), e["t"])
    for peer, at in last_fault.items():
        if sent.get(peer, -math.inf) < at and end - at > IN_FLIGHT:
            why = f"peer {peer} sent nothing after its plug-in's fault at {at:.1f} s: {said}"
            return Finding("plugins", False, why)
    return Finding("plugins", True, f"{said}; each peer went on, and the game to its verdict (first: {first})")


def _leftovers(run: Run) -> Finding:
    if not run.live:
        return Finding("leftovers", None, "a simulated run starts no process")
    try:
        started = processes.recorded(run.directory)
    except ValueError as exc:
        return Finding("leftovers", None, f"cannot tell: {exc}")
    if started is None:
        return Finding(
            "leftovers",
            None,
            f"cannot tell: this run recorded no processes (it has no {processes.PROCESSES}: "
            "a run from before runs recorded them)",
        )
    if any(p.host != processes.host() for p in started):
        return Finding(
            "leftovers",
            None,
            "cannot tell: the run's processes ran under another boot or PID namespace than this check's "
            "(another machine, a restart, a container)",
        )
    left = [f"{p.name} (pid {p.pid})" for p in started if processes.running(p)]
    left += _network_left(run)
    if left:
        return Finding("leftovers", False, f"left behind: {', '.join(left)}")
    if run.kernel:
        return Finding("leftovers", True, "no process, link or route of the run is left")
    return Finding("leftovers", True, "no process of the run is left")


def _network_left(run: Run) -> list[str]:
    """The link and route a kernel run added to the host (``endpoint.json``), if still there.
    A link is the run's while it has the interface number the run recorded
    (the next run takes the same name), and its route goes with it. The
    run's namespaces, and the packet rules inside them, end with their last
    process: a process left is what would keep them."""
    try:
        added = json.loads((run.directory / "endpoint.json").read_text()).get("network") or {}
    except (FileNotFoundError, json.JSONDecodeError):
        return []
    link = added.get("link")
    try:
        if link is None or int(Path(f"/sys/class/net/{link}/ifindex").read_text()) != added.get("ifindex"):
            return []
    except OSError:
        return []
    left = [f"link {link}"]
    if added.get("route"):
        routes = subprocess.run(["ip", "-j", "-4", "route"], capture_output=True, text=True).stdout or "[]"
        if any(r.get("dst") == added["route"] and r.get("dev") == link for r in json.loads(routes)):
            left.append(f"route {added['route']}")
    return left


def detected_after(directory: str | Path | Run) -> dict[int, float]:
    """Seconds from each fault that takes a peer away to the launcher seeing it gone, by fault index."""
    run = directory if isinstance(directory, Run) else Run(Path(directory))
    lease = run.scenario.lease if run.scenario is not None else 10.0
    found = {}
    for fault in run.faults:
        peers = [p for p in fault.get("peers", []) if p != GROUND] or fault.get("peers", [])
        if fault["kind"] in DETECTABLE and peers:
            seen = _first(run, peers[0], "gone", fault["t"])
            until = min(run.ended.get(fault["fault"], math.inf), fault["t"] + lease) + SLACK
            if seen is not None and seen <= until:
                found[fault["fault"]] = seen - fault["t"]
    return found


# ---------------------------------------------------------------- helpers


def _kind(key: str) -> str | None:
    try:
        return keys.parse(key).kind
    except BusError:
        return None


def _agent_of(key: str) -> str | None:
    try:
        return keys.parse(key).agent
    except BusError:
        return None


def _cut_off(run: Run, t: float, *peers: str) -> bool:
    """Whether a fault had one of ``peers`` (agent names) cut off at ``t``."""
    lease = run.scenario.lease if run.scenario is not None else 10.0
    names = {(GROUND if p in (*GROUND_AGENTS, LAUNCHER) else p) for p in peers}
    for fault in run.faults:
        start, end = fault["t"], run.ended.get(fault["fault"], math.inf)
        hit = names & set(fault.get("peers", [])) or fault["kind"] == "partition"
        if hit and start - 0.5 <= t <= end + lease:
            return True
    if any(start - 0.5 <= t <= end + lease for start, end in run.gaps):
        return True  # every peer died with the launcher
    return any(death["peer"] in names and start - 0.5 <= t <= end + lease for death, start, end in _absences(run))


def _absences(run: Run):
    """Each death no fault caused, with when it happened and when its peer
    was back on the bus (inf: never): a peer started again subscribes
    before its token comes, and what was sent before cannot reach it."""
    for death in run.deaths:
        again = next((e["t"] for e in run.restarts if e["peer"] == death["peer"] and e["t"] >= death["t"]), None)
        back = None if again is None else _first(run, death["peer"], "alive", again)
        yield death, death["t"], math.inf if back is None else back


def _lasted(run: Run, fault: dict) -> float | None:
    """How long a fault held: to its end, or to the end of the game if it outlived it."""
    end = run.ended.get(fault["fault"], _game_end(run))
    return None if end is None else end - fault["t"]


def _first(run: Run, peer: str, what: str, after: float) -> float | None:
    """When the launcher's side first saw a token of ``peer`` come (``alive``) or go, from ``after`` on."""
    for e in run.seen:
        agent = _agent_of(e["key"])
        owner = GROUND if agent in GROUND_AGENTS else agent
        if e["event"] == what and owner == peer and e["t"] >= after - 1e-9:
            return e["t"]
    return None


def _guided(run: Run, peers: list[str], after: float) -> float | None:
    """When one of ``peers`` first received guidance from ``after`` on."""
    times = [
        e["t"]
        for e in run.records()
        if e["event"] == "received" and e["receiver"] in peers and _kind(e["key"]) == "guidance" and e["t"] >= after
    ]
    return min(times, default=None)


def _stopped_for_a_reason(run: Run) -> bool:
    """Whether the run's outcome names why it has no verdict: a fault of its plan hit a peer the game
    needs, or supervision gave a peer up."""
    if run.outcome is None:
        return False
    reason = run.outcome.get("reason", "")
    return "fault[" in reason or any(e["gives_up"] and e["why"] == reason for e in run.deaths)


def _game_end(run: Run) -> float | None:
    ended = [
        e["t"]
        for e in run.events
        if e["event"] == "sent" and _kind(e["key"]) == "state" and e["message"]["phase"] == "ended"
    ]
    return min(ended) if ended else None


def _launcher_died(run: Run) -> str:
    """When the launcher of a run without an outcome died, as its peers saw it."""
    assert run.launcher_died is not None
    states = [e["message"] for e in run.events if e["event"] == "sent" and _kind(e["key"]) == "state"]
    running = next((m for m in states if m["phase"] != "waiting"), None)
    when = "before the game started"
    if running is not None:
        when = f"{run.launcher_died - (running['t'] - running['elapsed']):.1f} s into the game"
    return f"the launcher died {when}, and no bearcat run --resume took the run up"


def _run_end(run: Run) -> float:
    """When the game ended, or failing that the launcher's last record."""
    end = _game_end(run)
    return end if end is not None else max((e["t"] for e in run.events), default=math.inf)


def _ground_losses(run: Run, uav: str):
    """When ``uav`` lost its ground station, and when it had it back (inf: never): each fault that cut them apart."""
    for fault in run.faults:
        cut = GROUND in fault.get("peers", []) and fault["kind"] in ("kill", "stop", "restart", "pause", "partition")
        if cut or (uav in fault.get("peers", []) and fault["kind"] in ("partition", "outage")):
            yield fault["t"], run.ended.get(fault["fault"], math.inf)
    for death, start, end in _absences(run):
        if death["peer"] == GROUND:
            yield start, end


def _truth(run: Run, until: float) -> dict[str, list[tuple[float, np.ndarray]]]:
    """Each agent's true positions (local metres, by log time) in the last ``WINDOW`` up to ``until``."""
    game_map = run.scenario.map
    track: dict[str, list] = {}
    for e in run.events:
        if e["event"] == "sent" and _kind(e["key"]) == "truth" and e["t"] <= until + 1e-9:
            m = e["message"]
            points = track.setdefault(m["agent"], [])
            points.append((e["t"], np.array(game_map.to_local(m["lat"], m["lon"]))))
            while len(points) > 2 and points[1][0] < until - WINDOW:
                del points[0]
    return track


def _longest_step(points: list[tuple[float, np.ndarray]]) -> float:
    return max((float(np.hypot(*(b - a))) for (_, a), (_, b) in itertools.pairwise(points)), default=0.0)


def _closest(a: list[tuple[float, np.ndarray]], b: list[tuple[float, np.ndarray]]) -> float:
    """How close two tracks came, each moving straight between its samples, over the time both span.

    With a single sample each (a synchronous referee's last step is its
    last two samples) this is the referee's own sweep.
    """
    if len(a) == 1 or len(b) == 1:
        return float(min(np.hypot(*(p - q)) for _, p in a for _, q in b))
    ta, pa = np.array([t for t, _ in a]), np.array([p for _, p in a])
    tb, pb = np.array([t for t, _ in b]), np.array([p for _, p in b])
    start, end = max(ta[0], tb[0]), min(ta[-1], tb[-1])
    if end <= start:  # no overlap in time: the last step of each, as the referee swept them
        return _swept(pa[-2:], pb[-2:])
    times = np.unique(np.concatenate([[start, end], ta[(ta > start) & (ta < end)], tb[(tb > start) & (tb < end)]]))
    at = np.column_stack([np.interp(times, ta, pa[:, i]) for i in range(2)])
    bt = np.column_stack([np.interp(times, tb, pb[:, i]) for i in range(2)])
    return min(_swept(at[k : k + 2], bt[k : k + 2]) for k in range(len(times) - 1))


def _swept(a: np.ndarray, b: np.ndarray) -> float:
    """The closest two points come moving straight from a[0], b[0] to a[1], b[1] together."""
    d0, dd = a[0] - b[0], (a[1] - a[0]) - (b[1] - b[0])
    s = 0.0 if not dd.any() else float(np.clip(-(d0 @ dd) / (dd @ dd), 0.0, 1.0))
    return float(np.hypot(*(d0 + s * dd)))


def _contest(scenario):
    """What the referee of ``scenario`` judged by: radius, targets, forbidden regions."""

    return scenario.game_entry.factory(scenario).referee().contest
