"""What every agent is: a plain object the runtimes drive.

An agent names the key expressions it listens to and how often it ticks;
``handle`` takes one decoded message and ``tick`` the passage of time, and
both return the messages to send. ``peer`` tells it that a peer's
liveliness token appeared or vanished (for the agents that ``watch``).
No sockets, threads, sleeps or clocks inside: the simulation runtime calls
these in virtual time, the live one from its asyncio loop, and an agent
behaves the same in both. An exception out of any of these is the agent's
own bug: both runtimes record it as a ``failed`` event, send nothing for
that call and keep driving the agent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from bearcat.bus.messages import Message


@dataclass(frozen=True)
class Send:
    """A message to put on ``key`` (reliability follows from the key's kind)."""

    key: str
    message: Message


class Agent(Protocol):
    name: str  # the peer's session name
    role: str  # one of bus.keys.ROLES
    subscriptions: tuple[str, ...]  # key expressions
    watches: tuple[str, ...]  # liveliness key expressions
    period: float  # seconds between ticks

    def start(self, now: float) -> list[Send]: ...

    def handle(self, key: str, message: Message, now: float) -> list[Send]: ...

    def tick(self, now: float) -> list[Send]: ...

    def peer(self, key: str, alive: bool, now: float) -> list[Send]: ...
