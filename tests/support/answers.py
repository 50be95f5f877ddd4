"""A game's advisor asked as its guidance service asks it, for tests that
look at one form of its answers."""

import msgspec

from bearcat.agents.ground_station.guidance.method import GuidanceView


def answering(advisor, form: str = "plain"):
    """``advisor``'s ``form`` (plain, worst_case or calibrated) as a call
    ``(agent, fixes, now)`` returning the fields of the ``Guidance`` it
    fills, less those it leaves empty (None, no lines, no note)."""

    def answer(agent, fixes, now):
        view = GuidanceView(agent, now, fixes.map, fixes, advisor, {}, {})
        fields = msgspec.structs.asdict(getattr(advisor, form)(view))
        return {"game": advisor.kind} | {k: v for k, v in fields.items() if v is not None and v != [] and v != ""}

    return answer
