"""What one sender may cost a receiver: a token bucket per sender and key.

On a field network the opponent shares the bus, and a peer that floods one
key (twenty thousand messages a second) must not fill the receiver's disk
with its log, nor its memory, nor its processor. Each (sender, key) may
deliver ``rate`` messages a second on average and ``burst`` at once: a
stalled TCP stream that catches up arrives in a burst, and seconds of a
50 Hz stream must pass. What goes over is dropped before it is decoded,
counted per sender and key, and said once a second, not once a message.
"""

from __future__ import annotations

RATE = 100.0  # messages a second one sender may put on one key: twice the fastest legitimate stream
BURST = 500.0  # messages at once: ten seconds of a 50 Hz stream held behind a stall
BUCKETS = 4096  # (sender, key) pairs kept apart; a sender's name is its own claim, so the rest share one


class SenderBudget:
    """Token buckets per ``(sender, key)``; ``over`` counts what each went over by."""

    def __init__(self, rate: float = RATE, burst: float = BURST) -> None:
        self.rate, self.burst = float(rate), float(burst)
        self.over: dict[tuple[str, str], int] = {}
        self._buckets: dict[tuple[str, str], list[float]] = {}  # (sender, key) -> [tokens, when]
        self._unsaid: dict[tuple[str, str], int] = {}
        self._said_at = -float("inf")

    def allow(self, sender: str, key: str, now: float) -> bool:
        """Whether a message ``sender`` put on ``key`` may go through at ``now``."""
        if (sender, key) not in self._buckets and len(self._buckets) >= BUCKETS:
            sender, key = "*", "*"
        bucket = self._buckets.get((sender, key))
        if bucket is None:
            bucket = self._buckets[(sender, key)] = [self.burst, now]
        tokens = min(self.burst, bucket[0] + (now - bucket[1]) * self.rate)
        bucket[1] = now
        if tokens >= 1.0:
            bucket[0] = tokens - 1.0
            return True
        bucket[0] = tokens
        self.over[(sender, key)] = self.over.get((sender, key), 0) + 1
        self._unsaid[(sender, key)] = self._unsaid.get((sender, key), 0) + 1
        return False

    def news(self, now: float, every: float = 1.0) -> dict[tuple[str, str], int]:
        """What went over since it was last said, at most once every ``every`` s (empty otherwise)."""
        if not self._unsaid or now - self._said_at < every:
            return {}
        said, self._unsaid, self._said_at = self._unsaid, {}, now
        return said
