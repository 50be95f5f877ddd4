"""The field studies of thesis 3.5 as batches of simulated games.

``fake-out`` (3.5.1): the aided attacker, starting in a defender-winning
position, fakes out an unaided defender, and tries the same against an
aided one. ``go-no-go`` (3.5.2): an attacker waiting by cover commits when
its display says go; a go the game then loses is a false go, and how often
those happen depends on the network profile. ``search`` (6.2.4): the UAV
looks for the defender the attacker cannot see, guided by reachability,
sweeping like a lawnmower, or going to the nearest place the defender may
be; how soon the defender is found, and how often the attacker wins.

Each game is one task of the resumable batch runner, seeded on its own, so
any game can be replayed with ``bearcat simulate SCENARIO --seed S --netem P``.
"""

from __future__ import annotations

import statistics
from collections import defaultdict

STUDIES = {
    "fake-out": {"scenarios": ("fake-out", "fake-out-aided-defender"), "profiles": (None,)},
    "go-no-go": {"scenarios": ("go-no-go",), "profiles": ("ideal", "wifi", "3g", "3g-degraded")},
    "search": {"scenarios": ("search",), "profiles": (None,), "searches": ("reachability", "lawnmower", "nearest")},
}


def study_tasks(study: str, trials: int, seed: int, profiles=None, transports=None) -> list[dict]:
    """The games of ``study``: per scenario, profile, transport (None: the scenario's) and search, ``trials`` seeds."""
    spec = STUDIES[study]
    tasks = []
    for scenario in spec["scenarios"]:
        for profile in profiles or spec["profiles"]:
            for transport in transports or (None,):
                for search in spec.get("searches", (None,)):
                    for s in range(seed, seed + trials):
                        parts = (scenario, profile or "own", transport, search, s)
                        key = "/".join(str(part) for part in parts if part is not None)
                        tasks.append(
                            {"key": key, "scenario": scenario, "netem": profile, "transport": transport}
                            | {"seed": s, "search": search}
                        )
    return tasks


def play_task(task: dict) -> dict:
    """One game of a study; the result row. ``true_value`` is the solver's
    value at the true positions when the attacker went (negative: the window
    its display showed was really there)."""
    import tempfile
    from dataclasses import asdict, replace

    import msgspec

    from bearcat.scenarios.schema import load_scenario
    from bearcat.scenarios.simulate import simulate

    scenario = load_scenario(task["scenario"])
    if task.get("search") is not None:
        scenario = replace(
            scenario, uavs=tuple(msgspec.structs.replace(u, search=task["search"]) for u in scenario.uavs)
        )
    with tempfile.TemporaryDirectory() as tmp:
        events = f"{tmp}/events.jsonl"
        outcome = simulate(
            scenario, seed=task["seed"], netem=task["netem"], transport=task.get("transport"), events=events
        )
        keep = ("winner", "reason", "elapsed", "netem", "transport", "notes")
        row = {k: v for k, v in asdict(outcome).items() if k in keep}
        went = outcome.notes.get("attacker.went_at", outcome.notes.get("attacker.committed_at"))
        true_value = None if went is None else _true_value(scenario, events, went)
    found = [v for k, v in outcome.notes.items() if k.endswith(".found_at")]
    return {
        **row,
        "key": task["key"],
        "scenario": task["scenario"],
        "seed": task["seed"],
        "went_at": went,
        "true_value": true_value,
        "search": task.get("search"),
        "found_at": min(found) if found else None,
    }


def _true_value(scenario, events: str, t: float) -> float | None:
    """The capture-the-flag value at the players' true positions at time ``t``."""
    from bearcat.agents.ground_station.event_log import read_events
    from bearcat.scenarios.cast import _CtfGame

    if scenario.game != "ctf":
        return None
    where = {}
    for e in read_events(events):
        if e["event"] == "sent" and e["message"].get("type") == "truth" and e["t"] <= t + 1e-9:
            m = e["message"]
            where[m["agent"]] = scenario.map.to_local(m["lat"], m["lon"])
    game = _CtfGame(scenario)
    if game.attacker.id not in where or game.defender.id not in where:
        return None
    return round(float(game.solved().evaluate(where[game.attacker.id], where[game.defender.id], game.phase).value), 3)


def summarise(results) -> list[dict]:
    """Per scenario and profile: games, attacker wins, goes (the attacker
    committed), goes that won, false goes (committed, then lost), and rates;
    goes whose window was really there (the attacker's true position wins
    against the defender's) and how many of those the attacker won."""
    groups = defaultdict(list)
    for r in results:
        groups[(r["scenario"], r["netem"], r.get("transport", "tcp"))].append(r)
    rows = []
    for (scenario, netem, transport), games in sorted(groups.items()):
        wins = sum(g["winner"] == "attacker" for g in games)
        went = [g for g in games if g["went_at"] is not None]
        good = sum(g["winner"] == "attacker" for g in went)
        real = [g for g in went if g.get("true_value") is not None and g["true_value"] <= 0]
        rows.append(
            {
                "scenario": scenario,
                "netem": netem,
                "transport": transport,
                "games": len(games),
                "attacker_wins": wins,
                "attacker_win_rate": round(wins / len(games), 3),
                "attacker_win_interval": [round(x, 3) for x in wilson(wins, len(games))],
                "goes": len(went),
                "goes_won": good,
                "false_goes": len(went) - good,
                "false_go_rate": round((len(went) - good) / len(went), 3) if went else None,
                "median_go_time": _median([g["went_at"] for g in went]),
                "goes_really_open": len(real),
                "really_open_won": sum(g["winner"] == "attacker" for g in real),
            }
        )
    return rows


def summarise_search(results) -> list[dict]:
    """Per search strategy: games, how many found the defender and how soon
    (median and mean seconds of game time, over the games that found it),
    and the attacker's wins."""
    groups = defaultdict(list)
    for r in results:
        groups[r["search"]].append(r)
    rows = []
    for search, games in sorted(groups.items()):
        found = [g["found_at"] for g in games if g.get("found_at") is not None]
        wins = sum(g["winner"] == "attacker" for g in games)
        low, high = wilson(wins, len(games))
        rows.append(
            {
                "search": search,
                "games": len(games),
                "found": len(found),
                "median_time_to_find": _median(found),
                "mean_time_to_find": round(statistics.fmean(found), 2) if found else None,
                "attacker_wins": wins,
                "attacker_win_rate": round(wins / len(games), 3),
                "win_rate_95": [round(low, 3), round(high, 3)],
            }
        )
    return rows


def wilson(successes: int, trials: int) -> tuple[float, float]:
    """The 95 % Wilson score interval of a rate: games are chaotic enough
    that a different network draw turns many of them, so a rate from 50
    games is only good to about +-14 %."""
    from scipy.stats import binomtest

    interval = binomtest(successes, trials).proportion_ci(confidence_level=0.95, method="wilson")
    return float(interval.low), float(interval.high)


def _median(values: list[float]) -> float | None:
    return round(statistics.median(values), 2) if values else None
