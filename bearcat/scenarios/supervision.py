"""How a live run supervises its peers: which it starts again when they die,
how soon, and how often before it gives up.

A scenario's ``[supervision]`` table, after Erlang/OTP's supervisors (a
restart policy per child, an intensity of ``max_restarts`` within
``period``) and systemd's ``Restart=on-failure`` (a peer that exits with
code 0 ended as asked and is not started again)::

    [supervision]
    max_restarts = 3             # more unplanned deaths of one peer than this ...
    period = 60.0                # ... within this many seconds end the game
    backoff = 0.5                # s before the first restart; it doubles with each restart within the period
    backoff_max = 8.0            # s, the longest wait
    restart = { ground-station = "on-failure", uav = "on-failure", walker = "never", phone = "never" }

A dead walker is not started again by default: a player whose phone died
is gone, and the referee forfeits them once their lease to rejoin runs out,
as in the field. The ground station and a UAV's companion computer are the
team's equipment, which someone would reboot.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec
from msgspec import Meta

Policy = Literal["on-failure", "never"]
Seconds = Annotated[float, Meta(ge=0.0, le=3600.0, extra={"unit": "s"})]


class Restarts(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True, rename="kebab"):
    """Each role's restart policy."""

    ground_station: Policy = "on-failure"
    uav: Policy = "on-failure"
    walker: Policy = "never"
    phone: Policy = "never"

    def of(self, role: str) -> Policy:
        """The policy of peers in ``role`` (a peer spec's role)."""
        return getattr(self, role.replace("-", "_"))


class Supervision(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """The ``[supervision]`` table."""

    restart: Restarts = Restarts()
    max_restarts: Annotated[int, Meta(ge=0, le=1000)] = 3
    period: Annotated[float, Meta(gt=0.0, le=86400.0, extra={"unit": "s"})] = 60.0
    backoff: Seconds = 0.5
    backoff_max: Seconds = 8.0

    def wait(self, recent: int) -> float:
        """Seconds before the restart that follows ``recent`` restarts within the period."""
        return min(self.backoff * 2.0**recent, max(self.backoff, self.backoff_max))
