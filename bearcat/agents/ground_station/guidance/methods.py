"""The built-in guidance methods, entries of ``method.GUIDANCE_METHODS``
exactly as a user's own are. Each is one way of treating the stale, noisy
fixes the network delivered, and answers with its game's advisor's form of
that name:

- ``none``: the fixes are taken as exact, as in the thesis;
- ``worst-case``: each player is anywhere in the disk its last fix allows,
  and the answer holds against all of it;
- ``calibrated``: the players are where their trackers predict them now,
  and what the prediction gets wrong is paid for as measured (``bearcat
  calibrate``).

``guidance.ctf`` says what each means for capture-the-flag; reach-avoid
has the first two, pursuit the first.
"""

from __future__ import annotations

from bearcat.agents.ground_station.guidance.method import TRACKS, Advice, GuidanceMethod, GuidanceView


class Plain(GuidanceMethod):
    """Answer at the positions as reported, as the thesis's ground station did."""

    needs = frozenset({"plain"})

    def advise(self, view: GuidanceView) -> Advice:
        return view.answers.plain(view)


class WorstCase(GuidanceMethod):
    """Answer against every place each player may be since its last fix, at its top speed and GPS error."""

    needs = frozenset({"worst_case"})

    def advise(self, view: GuidanceView) -> Advice:
        return view.answers.worst_case(view)


class Calibrated(GuidanceMethod):
    """Answer where the trackers predict the players now, the attacker's go with a margin measured on games."""

    traits = frozenset({TRACKS})
    needs = frozenset({"calibrated"})

    def advise(self, view: GuidanceView) -> Advice:
        return view.answers.calibrated(view)


BUILTINS: dict[str, type] = {"none": Plain, "worst-case": WorstCase, "calibrated": Calibrated}
"""The built-in entries of ``GUIDANCE_METHODS``, by the names scenarios give them."""
