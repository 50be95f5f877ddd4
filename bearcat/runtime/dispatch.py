"""How a runtime drives its agents, the same in simulation and live.

What arrives for an agent is decoded through its inbox (a payload it refuses
is recorded as ``refused``), recorded as ``received`` and handed to the agent;
what the agent answers is recorded as ``sent`` and put on its session. The
runtimes differ only in their clock and transport, not in this sequence.

An agent that raises, in ``start``, ``handle``, ``tick`` or ``peer``, has a
bug of its own; the peer it runs in goes on. The exception is counted per
agent, recorded as a ``failed`` event (the agent, the key it was handling or
``start``, ``tick``, and the exception's type and text) and logged with its
traceback the first time and every hundredth after, so a tick that always
fails cannot flood the log. Nothing is sent for the call that failed.

What one sender puts on one key is held to a budget per receiving agent
(``bus.budget``): a flood is dropped before it is decoded, and said once a
second in the event log (``over-budget``), so it cannot fill the disk. So is
what a live peer's session refused to believe, by the sender it claimed.

What an agent did on its own and keeps in its ``events`` list (a UAV's
failsafe, its landing) is recorded as ``did`` events, as it happens; a
plug-in's fault that its guard kept there, as a ``plugin`` event.

An agent whose peer's clock is wrong (a clock fault) is handed its own
time (``clocks``); the record keeps the runtime's.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from typing import TYPE_CHECKING

from bearcat.agents.guard import PluginFault
from bearcat.agents.protocol import Agent, Send
from bearcat.bus import keys
from bearcat.bus.budget import SenderBudget
from bearcat.bus.codec import Inbox, encode
from bearcat.bus.messages import Message

if TYPE_CHECKING:
    from bearcat.bus.inprocess import LocalSession
    from bearcat.bus.zenoh_session import ZenohSession

log = logging.getLogger(__name__)

FAILED = "failed"  # the event kind of an agent's exception in the event log
DID = "did"  # the event kind of what an agent did on its own
PLUGIN = "plugin"  # the event kind of a plug-in's fault (agents.guard)


class Dispatcher:
    """Drives agents, each on the session it was attached with, recording
    into ``record`` (an ``EventLog``) at the times ``now()`` gives."""

    def __init__(self, record, now: Callable[[], float]) -> None:
        self.record = record
        self.now = now
        self.failures: Counter[str] = Counter()  # agent -> exceptions raised
        self.plugin_faults: Counter[str] = Counter()  # "agent/plug-in/fault" -> how many
        self.clocks: dict[str, Callable[[float], float]] = {}  # agent -> its own time from the runtime's
        self._sessions: dict[str, LocalSession | ZenohSession] = {}
        self._inboxes: dict[str, Inbox] = {}
        self._told: dict[str, int] = {}  # agent -> how many of its events are recorded
        self._budgets: dict[str, SenderBudget] = {}
        self._unbelieved = SenderBudget()  # what a peer's session would not believe, by the sender it claimed

    def attach(self, agent: Agent, session: LocalSession | ZenohSession) -> None:
        """Drive ``agent`` on ``session`` (peers that run several agents share one)."""
        self._sessions[agent.name] = session
        self._inboxes[agent.name] = Inbox(agent.name)
        self._budgets[agent.name] = SenderBudget()
        self._told[agent.name] = 0

    def session_of(self, name: str):
        """The session agent ``name`` was attached to."""
        return self._sessions[name]

    @property
    def drops(self) -> dict[str, dict[str, int]]:
        """Per agent that had to drop anything, its drops by reason."""
        return {name: dict(inbox.drops) for name, inbox in self._inboxes.items() if inbox.dropped}

    def start(self, agent: Agent) -> None:
        self._publish(agent, self._call(agent, "start", agent.start, self._now(agent)))

    def tick(self, agent: Agent) -> None:
        self._publish(agent, self._call(agent, "tick", agent.tick, self._now(agent)))

    def peer(self, agent: Agent, key: str, alive: bool) -> None:
        self._publish(agent, self._call(agent, key, agent.peer, key, alive, self._now(agent)))

    def _now(self, agent: Agent) -> float:
        clock = self.clocks.get(agent.name)
        return self.now() if clock is None else clock(self.now())

    def receive(self, agent: Agent, key: str, payload: bytes, sender: str) -> Message | None:
        """Hand what arrived on ``key`` to ``agent``; the decoded message, None if refused."""
        now = self.now()
        budget = self._budgets[agent.name]
        if not budget.allow(sender, key, now):
            self._inboxes[agent.name].drops["over budget"] += 1
            for (who, where), n in budget.news(now).items():
                self.record.note(now, "over-budget", sender=who, receiver=agent.name, key=where, dropped=n)
            return None
        message = self._inboxes[agent.name].accept(key, payload)
        if message is None:
            self.record.refused(now, sender, agent.name, key, "undecodable or wrong for its key")
            return None
        self.record.received(now, sender, agent.name, key, getattr(message, "seq", None))
        self._publish(agent, self._call(agent, key, agent.handle, key, message, self._now(agent)))
        return message

    def unbelieved(self, receiver: str, key: str, claimed: str, reason: str) -> None:
        """Record a message ``receiver``'s session refused (its seal did not
        hold), within what the sender it claimed may cost."""
        now = self.now()
        if self._unbelieved.allow(claimed, key, now):
            self.record.refused(now, claimed, receiver, key, reason)
            return
        for (who, where), n in self._unbelieved.news(now).items():
            self.record.note(now, "over-budget", sender=who, receiver=receiver, key=where, dropped=n)

    def _call(self, agent: Agent, where: str, method, *args) -> list[Send]:
        try:
            return method(*args)
        except Exception as exc:
            self.failures[agent.name] += 1
            n = self.failures[agent.name]
            reason = str(exc)[:200]
            self.record.note(
                self.now(), FAILED, agent=agent.name, key=where, exception=type(exc).__name__, reason=reason
            )
            if n == 1 or n % 100 == 0:
                log.error("%s failed on %s (%d so far)", agent.name, where, n, exc_info=True)
            return []

    def _publish(self, agent: Agent, sends: list[Send]) -> None:
        did = getattr(agent, "events", None)
        if did:
            for event in did[self._told.get(agent.name, 0) :]:
                if isinstance(event, PluginFault):
                    fields = {k: v for k, v in vars(event).items() if k != "t"}
                    self.record.note(self.now(), PLUGIN, at=event.t, peer=self._sessions[agent.name].name, **fields)
                    self.plugin_faults[f"{event.agent}/{event.plugin}/{event.fault}"] += 1
                else:
                    t, what = event
                    self.record.note(self.now(), DID, agent=agent.name, at=t, what=what)
            self._told[agent.name] = len(did)
        session = self._sessions[agent.name]
        for s in sends:
            payload = encode(s.message)
            self.record.sent(self.now(), session.name, s.key, s.message, size=len(payload))
            session.put(s.key, payload, reliable=keys.reliable(s.key))
