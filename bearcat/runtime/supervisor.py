"""What a live run does when one of its peers dies and no fault plan asked for it.

The decision alone, on a clock it is handed: the launcher (``live_run``)
watches the processes, records each death and restart, and starts the
peer again, resuming from its own log as a planned ``restart`` does.
"""

from __future__ import annotations

from dataclasses import dataclass

from bearcat.scenarios.supervision import Supervision


@dataclass(frozen=True)
class Death:
    """A peer's unplanned death: started again after ``wait`` s, or not, and why."""

    peer: str
    code: int
    restart: bool
    wait: float
    gives_up: bool  # the peer died too often: the run ends
    why: str


class Supervisor:
    """The ``policy`` for a run's peers."""

    def __init__(self, policy: Supervision) -> None:
        self.policy = policy
        self._restarts: dict[str, list[float]] = {}  # peer -> when each of its deaths was restarted

    def died(self, peer: str, role: str | None, code: int, now: float) -> Death:
        """``peer``, in ``role`` (None: a process that is no peer, such as a
        UAV's vehicle, which is not the run's to start again), exited with
        ``code`` at ``now``: what follows."""
        if code == 0:
            return Death(peer, code, False, 0.0, False, "it exited as asked (code 0)")
        if role is None or self.policy.restart.of(role) == "never":
            return Death(peer, code, False, 0.0, False, f"{role or 'its role'}s are not restarted")
        p = self.policy
        recent = [t for t in self._restarts.get(peer, []) if now - t < p.period]
        if len(recent) >= p.max_restarts:
            why = (
                f"peer {peer} restarted too often: {len(recent) + 1} unplanned deaths within {p.period:g} s "
                f"(max_restarts {p.max_restarts}), the last with code {code}"
            )
            return Death(peer, code, False, 0.0, True, why)
        self._restarts[peer] = [*recent, now]
        wait = p.wait(len(recent))
        return Death(peer, code, True, wait, False, f"restart {len(recent) + 1} within {p.period:g} s")
