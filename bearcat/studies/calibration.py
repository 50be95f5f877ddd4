"""Calibration games: simulated games whose answers are scored against the truth.

Each game is played with the thesis's guidance (``method = "none"``
for every agent), so that what is measured does not depend on an earlier
calibration. Its event log is then replayed through what a calibrated
ground station keeps: the fixes the ground station received, in the order
and at the times it received them, into the trackers, and the phase from
the referee's states. At every guidance the ground station sent the
attacker, the value at the trackers' prediction (what calibrated guidance
would have used) is scored against the value at the players' true
positions then (``calibration.Score``).

Seeds: a calibration plays ``seed, seed + 1, ...`` (``bearcat calibrate``
starts at ``CALIBRATION_SEED``, far from the 0-199 the studies play), and
checks its coverage on the seeds after those, which it never fitted.
"""

from __future__ import annotations

import math

import numpy as np

from bearcat.agents.ground_station.calibration import Score
from bearcat.agents.ground_station.guidance.ctf import CtfAdvisor
from bearcat.agents.ground_station.guidance.fixes import LatestFixes
from bearcat.bus import keys
from bearcat.bus.messages import Fix
from bearcat.netem.profiles import Profile
from bearcat.scenarios.cast import ctf_of, tracking
from bearcat.scenarios.schema import Scenario
from bearcat.solvers.ctf.queries import CtfQueries
from bearcat.solvers.errors import InputError

CALIBRATION_SEED = 100_000
"""The first seed ``bearcat calibrate`` plays by default: disjoint from every study's."""


def calibration_tasks(
    scenario: str, netem: str, first: int, count: int, part: str, ablate: list[str] | None = None
) -> list[dict]:
    """One task per game of seeds ``first`` to ``first + count - 1``, of
    ``part`` ("fit" or "check"), scored through trackers less ``ablate``."""
    tag = "".join(f"|no-{a}" for a in ablate or ())
    return [
        {
            "key": f"{scenario}|{netem}{tag}|{seed}",
            "scenario": scenario,
            "netem": netem,
            "seed": seed,
            "part": part,
            "ablate": list(ablate or ()),
        }
        for seed in range(first, first + count)
    ]


def play_calibration_task(task: dict) -> dict:
    """Play one calibration game and score it: the result row, its scores as
    ``[t, phase, age, estimated, true]`` lists."""
    import tempfile

    from bearcat.netem.profiles import load_profile
    from bearcat.runtime.simulate import simulate
    from bearcat.scenarios.schema import load_scenario
    from bearcat.scenarios.variants import vary

    plain = {"guidance.method": "none", "agent.*.guidance": "none", "guidance.ablate": task.get("ablate", [])}
    scenario = vary(load_scenario(task["scenario"]), plain)
    profile = load_profile(task["netem"])
    with tempfile.TemporaryDirectory() as tmp:
        events = f"{tmp}/events.jsonl"
        outcome = simulate(scenario, seed=task["seed"], netem=task["netem"], events=events)
        from bearcat.agents.ground_station.event_log import read_events

        queries = ctf_of(scenario).solved()
        scores = replay_scores(scenario, profile, queries, read_events(events), task["seed"])
    return {
        "key": task["key"],
        "seed": task["seed"],
        "part": task["part"],
        "winner": outcome.winner,
        "scores": [[round(s.t, 3), s.phase, round(s.age, 3), round(s.estimated, 4), round(s.true, 4)] for s in scores],
    }


def scores_of(result: dict) -> list[Score]:
    """The scores of one calibration game's result row."""
    return [Score(result["seed"], t, phase, age, est, true) for t, phase, age, est, true in result["scores"]]


def replay_scores(scenario: Scenario, profile: Profile, queries: CtfQueries, events, game: int) -> list[Score]:
    """The scores of one game's event log (see the module's docstring)."""
    attacker, defender = (scenario.team(team)[0].id for team in ("attacker", "defender"))
    advisor = CtfAdvisor(scenario.map, queries, attacker=attacker, defender=defender)
    fixes = LatestFixes(scenario.map, tracking(scenario, profile)())
    sent_fixes: dict[tuple[str, int], dict] = {}
    sent_states: dict[int, dict] = {}
    truth: dict[str, np.ndarray] = {}
    running = False
    scores = []
    for event in events:
        kind, message = event["event"], event.get("message") or {}
        if kind == "sent":
            what = message.get("type")
            if what == "fix":
                sent_fixes[(message["agent"], message["seq"])] = message
            elif what == "state":
                sent_states[message["seq"]] = message
            elif what == "truth":
                truth[message["agent"]] = np.array(scenario.map.to_local(message["lat"], message["lon"]))
            elif what == "guidance" and message["agent"] == attacker and running:
                score = _score(advisor, fixes, truth, event["t"], attacker, defender, game)
                if score is not None:
                    scores.append(score)
        elif kind == "received" and event.get("receiver") == keys.GROUND:
            key = event["key"]
            if "/fix/" in key and (event["sender"], event["seq"]) in sent_fixes:
                fields = sent_fixes[(event["sender"], event["seq"])]
                fixes.take(Fix(**{k: v for k, v in fields.items() if k not in ("type", "v")}))
            elif key.endswith("/state") and event["seq"] in sent_states:
                state = sent_states[event["seq"]]
                running = state["phase"] == "running"
                advisor.phase = "capture" if state["flag_holder"] is None else "return"
    return scores


def _score(advisor: CtfAdvisor, fixes: LatestFixes, truth, t: float, attacker: str, defender: str, game: int):
    estimate = advisor.estimate(fixes, t)
    if estimate is None or attacker not in truth or defender not in truth:
        return None
    try:
        estimated = advisor.estimated_value(estimate)
        a, d = advisor.placeable(truth[attacker]), advisor.placeable(truth[defender])
        true = float(advisor.solved.evaluate(a, d, advisor.phase).value)
    except InputError:
        return None
    if not (math.isfinite(estimated) and math.isfinite(true)):
        return None
    return Score(game, float(t), advisor.phase, float(estimate.age), estimated, true)
