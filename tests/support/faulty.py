"""A real agent with a bug injected: it raises on the messages a test picks
and on every Nth tick, and otherwise behaves as the agent it wraps."""


class Faulty:
    """``agent``, except that ``handle`` raises ``RuntimeError`` on the messages
    ``fails_on(key, message)`` picks and ``tick`` raises ``ZeroDivisionError``
    on every ``every``-th tick; ``raised`` counts both."""

    def __init__(self, agent, *, fails_on=lambda key, message: False, every: int = 0) -> None:
        self.agent = agent
        self.fails_on = fails_on
        self.every = every
        self.ticks = 0
        self.raised = 0

    def __getattr__(self, name):
        return getattr(self.agent, name)

    def start(self, now):
        return self.agent.start(now)

    def handle(self, key, message, now):
        if self.fails_on(key, message):
            self.raised += 1
            raise RuntimeError(f"no answer to {type(message).__name__} seq {getattr(message, 'seq', None)}")
        return self.agent.handle(key, message, now)

    def tick(self, now):
        self.ticks += 1
        if self.every and self.ticks % self.every == 0:
            self.raised += 1
            raise ZeroDivisionError(f"tick {self.ticks} divided by zero")
        return self.agent.tick(now)

    def peer(self, key, alive, now):
        return self.agent.peer(key, alive, now)
