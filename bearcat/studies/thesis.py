"""The studies: batches of simulated games that measure what guidance buys.

- ``fake-out`` (thesis 3.5.1): the aided attacker, starting in a
  defender-winning position, feints until its display shows a window. The
  unaided defender's outcome is mapped over the human factors that decide
  it: how far in front of the attacker it marks, how late it reacts, how
  often the phones report; the aided defender, on plain, worst-case and
  calibrated guidance, gives the reference rows.
- ``holding``: the aided defender from the fake-out starts, its guidance
  plain, worst-case or calibrated (``guidance.method``), per network
  profile and report rate.
- ``go-no-go`` (3.5.2): an attacker waiting by cover commits when its
  display says go; a go the game then loses is a false go. Plain against
  worst-case and calibrated guidance, per network profile.
- ``search`` (6.2.4): the UAV looks for the defender the attacker cannot see,
  guided by reachability, sweeping like a lawnmower, or going to the nearest
  place the defender may be; how soon it is found, how often the attacker wins.

A study is a set of cells, each a built-in scenario with some keys changed
(``scenarios.variants``) and labels naming the change, played on each of the
study's network profiles for a run of seeds. Each game is one task of the
resumable batch runner, seeded on its own, so any game can be replayed with
``bearcat simulate SCENARIO --seed S --netem P`` on the changed scenario.
"""

from __future__ import annotations

import json
import statistics
from collections import defaultdict
from dataclasses import dataclass, field

PROFILES = ("ideal", "wifi", "3g", "3g-degraded")

GUIDANCE = {
    "plain": {"method": "none", "confidence": 0.95},
    "worst-case": {"method": "worst-case", "confidence": 0.95},
    "worst-case, age only": {"method": "worst-case", "confidence": 0.0},
    "calibrated": {"method": "calibrated", "confidence": 0.95},
}
"""The guidance a study compares: answers at the reports as they are; the
worst case over where the players may be, GPS error included (its 95 %
circle), or over how far they may have moved only; and answers at where
the trackers predict them, with the calibrated margin (``bearcat calibrate``
on the same scenario and profile, else the tracker's own)."""
ABLATED = {
    f"calibrated, no {part}": GUIDANCE["calibrated"] | {"ablate": [part]}
    for part in ("prediction", "bias", "manoeuvre", "calibration", "belief")
}
"""Calibrated guidance with one part switched off (``guidance.ablate``), to
measure what that part gives. A study plays these only when asked by name."""
STUDY_ABLATIONS = {
    "holding": ("prediction", "bias", "manoeuvre", "belief"),
    "go-no-go": ("prediction", "bias", "manoeuvre", "calibration"),
}
"""The parts whose ablation a study offers: the defender's holding uses no
calibration, the attacker's go no belief quantile."""

CAUGHT, OUT_OF_TIME = " captured", "time limit of "
"""How the referee's reason for the end of a game ends when the defender
caught the attacker, and begins when the clock ran out."""

MARKING = (3.0, 6.0, 9.0, 12.0)
"""The unaided defender's marking distance (m in front of the attacker on its run home)."""
REACTION = (0.2, 0.4, 0.7, 1.0, 1.2)
"""The defender's reaction time (s): the range reported for people, 0.2 for a
simple cue to 1.2 for a choice under load."""
REPORT_RATES = (1.0, 2.0, 5.0, 10.0)
"""How often the phones report (Hz)."""
MAP_RATES = (1.0, 5.0)


@dataclass(frozen=True)
class Cell:
    """One arm of a study: ``scenario`` with ``changes``, shown by ``labels``."""

    scenario: str
    changes: dict = field(default_factory=dict)
    labels: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Study:
    """The cells of a study, the profiles they are played on (None: each
    scenario's own) and how its rows are grouped (``by``, label names)."""

    cells: tuple[Cell, ...]
    profiles: tuple[str | None, ...]
    by: tuple[str, ...]
    description: str


def _guidance(name: str, who: str | None) -> dict:
    """The changes that give ``who`` (None: everybody) guidance ``name``."""
    spec = (GUIDANCE | ABLATED)[name]
    key = "guidance.method" if who is None else f"agent.{who}.guidance"
    ablate = {"guidance.ablate": spec["ablate"]} if "ablate" in spec else {}
    return {key: spec["method"], "guidance.confidence": spec["confidence"]} | ablate


def _offered(study: str) -> list[str]:
    """The guidance ``study``'s cells vary over: every form, then its ablations."""
    return [*GUIDANCE, *(f"calibrated, no {part}" for part in STUDY_ABLATIONS[study])]


def _fake_out_cells() -> tuple[Cell, ...]:
    cells = []
    for rate in MAP_RATES:
        for reaction in REACTION:
            for marking in MARKING:
                changes = {
                    "agent.defender.options.standoff": marking,
                    "agent.defender.reaction": reaction,
                    "agent.*.fix_rate": rate,
                }
                labels = {"defender": "unaided", "marking": marking, "reaction": reaction, "rate": rate}
                cells.append(Cell("fake-out", changes, labels))
            for guidance in ("plain", "worst-case", "calibrated"):
                changes = _guidance(guidance, "defender") | {
                    "agent.defender.reaction": reaction,
                    "agent.*.fix_rate": rate,
                }
                labels = {
                    "defender": f"{guidance} aided",
                    "marking": None,
                    "reaction": reaction,
                    "rate": rate,
                    "guidance": guidance,
                }
                cells.append(Cell("fake-out-aided-defender", changes, labels))
    return tuple(cells)


def _search_cell(policy: str) -> Cell:
    """The search study's cell of UAV tasking ``policy`` (a plug-in name)."""
    return Cell("search", {"uav.*.search": policy}, {"search": policy})


STUDIES = {
    "fake-out": Study(
        _fake_out_cells(),
        (None,),
        ("defender", "marking", "reaction", "rate"),
        "the fake-out's outcome against the unaided defender over its marking distance, its reaction time and "
        "the phones' report rate, with the aided defender on plain, worst-case and calibrated guidance as the "
        "reference (3.5.1)",
    ),
    "holding": Study(
        tuple(
            Cell(
                "fake-out-aided-defender",
                _guidance(g, "defender") | {"agent.*.fix_rate": rate},
                {"guidance": g, "rate": rate},
            )
            for g in _offered("holding")
            for rate in REPORT_RATES
        ),
        PROFILES,
        ("guidance", "rate"),
        "how often the aided defender holds from the fake-out's starts, plain, worst-case and calibrated "
        "guidance, per network profile and report rate",
    ),
    "go-no-go": Study(
        tuple(Cell("go-no-go", _guidance(g, None), {"guidance": g}) for g in _offered("go-no-go")),
        PROFILES,
        ("guidance",),
        "how often an attacker's go, decided on what the network delivered, is false, per network profile, "
        "plain, worst-case and calibrated guidance (3.5.2)",
    ),
    "search": Study(
        tuple(_search_cell(s) for s in ("reachability", "lawnmower", "nearest")),
        (None,),
        ("search",),
        "reachability-guided UAV search against a lawnmower sweep and the nearest unobserved point: time until "
        "the defender is found, and the attacker's wins (6.2.4)",
    ),
}


def study_cells(study: str, guidance=None, search=None) -> tuple[Cell, ...]:
    """The cells of ``study``; with ``guidance`` (names of ``GUIDANCE`` or
    ``ABLATED``), only those of that guidance (so the fake-out map's aided
    rows can be played without its unaided ones); without, all but the
    ablations. ``search`` (tasking policies, built-in or one's own) gives
    the search study those cells instead of the thesis's three."""
    cells = tuple(_search_cell(p) for p in dict.fromkeys(search)) if search else STUDIES[study].cells
    if guidance is None:
        return tuple(c for c in cells if c.labels.get("guidance") not in ABLATED)
    return tuple(c for c in cells if c.labels.get("guidance") in guidance)


def study_guidance(study: str) -> list[str]:
    """The guidance names ``study``'s cells vary over, in order."""
    return list(dict.fromkeys(c.labels["guidance"] for c in STUDIES[study].cells if "guidance" in c.labels))


def study_rates(study: str) -> list[float]:
    """The report rates ``study``'s cells vary over, in order (none: it varies none)."""
    return sorted({c.labels["rate"] for c in STUDIES[study].cells if "rate" in c.labels})


def study_tasks(
    study: str,
    trials: int,
    seed: int,
    profiles=None,
    transports=None,
    guidance=None,
    rates=None,
    changes=None,
    search=None,
) -> list[dict]:
    """The games of ``study``: per cell (of ``guidance`` and ``rates``, if
    given; of the tasking policies ``search``, in the search study),
    profile, transport (None: the scenario's), ``trials`` seeds.
    ``changes`` (variant keys to values, ``scenarios.variants``) are made
    in every cell's scenario on top of its own, such as another behaviour
    for one side; they are part of each game's key, so a results file
    keeps the games with and without them apart."""
    spec = STUDIES[study]
    tasks = []
    for cell in study_cells(study, guidance, search):
        if rates is not None and cell.labels.get("rate") not in rates:
            continue
        if changes:
            cell = Cell(cell.scenario, cell.changes | changes, cell.labels | {"changes": _described(changes)})
        for profile in profiles or spec.profiles:
            for transport in transports or (None,):
                for s in range(seed, seed + trials):
                    tasks.append(game_task(cell, profile, transport, s))
    return tasks


def game_task(cell: Cell, profile: str | None, transport: str | None, seed: int) -> dict:
    """One game of ``cell``, keyed by everything that tells it from the others."""
    parts = [cell.scenario, profile or "own", transport, *(f"{k}={v}" for k, v in cell.labels.items()), seed]
    return {
        "key": "/".join(str(p) for p in parts if p is not None),
        "scenario": cell.scenario,
        "changes": cell.changes,
        "labels": cell.labels,
        "netem": profile,
        "transport": transport,
        "seed": seed,
    }


def _described(changes: dict) -> str:
    return ", ".join(f"{key} = {json.dumps(value)}" for key, value in changes.items())


def unplayable(tasks: list[dict]) -> str | None:
    """Why this process cannot play ``tasks``: the first of their
    scenarios, with its changes, that cannot be read here (a plug-in it
    names cannot be imported, say), in one sentence; None if all can."""
    from bearcat.scenarios.schema import ScenarioError, load_scenario
    from bearcat.scenarios.variants import vary

    seen = set()
    for task in tasks:
        cell = (task["scenario"], json.dumps(task.get("changes") or {}, sort_keys=True))
        if cell in seen:
            continue
        seen.add(cell)
        try:
            vary(load_scenario(task["scenario"]), task.get("changes") or {})
        except ScenarioError as exc:
            return str(exc)
    return None


def play_task(task: dict) -> dict:
    """One game of a study; the result row. ``true_value`` is the solver's
    value at the true positions when the attacker went (negative: the window
    its display showed was really there)."""
    import tempfile

    from bearcat.runtime.simulate import simulate
    from bearcat.scenarios.schema import load_scenario
    from bearcat.scenarios.variants import vary

    scenario = vary(load_scenario(task["scenario"]), task.get("changes") or {})
    with tempfile.TemporaryDirectory() as tmp:
        events = f"{tmp}/events.jsonl"
        outcome = simulate(
            scenario, seed=task["seed"], netem=task["netem"], transport=task.get("transport"), events=events
        )
        return game_row(task, scenario, outcome, events)


def game_row(task: dict, scenario, outcome, events) -> dict:
    """The result row of one game, simulated or live, from its outcome and event log."""
    went = outcome.notes.get("attacker.committed_at")
    true_value = None if went is None else _true_value(scenario, events, went)
    found = [v for k, v in outcome.notes.items() if k.endswith(".found_at")]
    return {
        "key": task["key"],
        "scenario": task["scenario"],
        "labels": task.get("labels") or {},
        "seed": task["seed"],
        "netem": outcome.netem,
        "transport": outcome.transport,
        "winner": outcome.winner,
        "reason": outcome.reason,
        "elapsed": outcome.elapsed,
        "notes": outcome.notes,
        "went_at": went,
        "true_value": true_value,
        "found_at": min(found) if found else None,
    }


def _true_value(scenario, events: str, t: float) -> float | None:
    """The capture-the-flag value at the players' true positions at time ``t``."""
    from bearcat.agents.ground_station.event_log import read_events
    from bearcat.scenarios.cast import _CtfGame, is_ctf

    if not is_ctf(scenario):
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


def summarise(results, by=()) -> list[dict]:
    """Per scenario, profile, transport and the labels named in ``by``:
    games, wins of each side with 95 % intervals, goes (the attacker
    committed), goes that won, false goes (committed, then lost) and their
    rate with its interval, split into those the defender caught and those
    the time limit ended on the way home (a late go, not a wrong one); goes
    whose window was really there (the attacker's true position wins
    against the defender's) and how many of those the attacker won."""
    groups = defaultdict(list)
    for r in results:
        labels = r.get("labels") or {}
        key = (r["scenario"], r["netem"], r.get("transport", "tcp"), *(labels.get(k) for k in by))
        groups[key].append(r)
    rows = []
    for key, games in sorted(groups.items(), key=lambda item: _group_order(item[0])):
        scenario, netem, transport, *labels = key
        wins = sum(g["winner"] == "attacker" for g in games)
        held = sum(g["winner"] == "defender" for g in games)
        went = [g for g in games if g["went_at"] is not None]
        good = sum(g["winner"] == "attacker" for g in went)
        lost = [g for g in went if g["winner"] != "attacker"]
        real = [g for g in went if g.get("true_value") is not None and g["true_value"] <= 0]
        rows.append(
            {
                "scenario": scenario,
                "netem": netem,
                "transport": transport,
                **dict(zip(by, labels)),
                "games": len(games),
                "attacker_wins": wins,
                "attacker_win_rate": round(wins / len(games), 3),
                "attacker_win_interval": _interval(wins, len(games)),
                "defender_wins": held,
                "defender_win_rate": round(held / len(games), 3),
                "defender_win_interval": _interval(held, len(games)),
                "goes": len(went),
                "goes_won": good,
                "false_goes": len(went) - good,
                "false_go_rate": round((len(went) - good) / len(went), 3) if went else None,
                "false_go_interval": _interval(len(went) - good, len(went)) if went else None,
                "false_goes_caught": sum(g["reason"].endswith(CAUGHT) for g in lost),
                "false_goes_out_of_time": sum(g["reason"].startswith(OUT_OF_TIME) for g in lost),
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
        groups[(r.get("labels") or {}).get("search", r.get("search"))].append(r)
    rows = []
    for search, games in sorted(groups.items()):
        found = [g["found_at"] for g in games if g.get("found_at") is not None]
        wins = sum(g["winner"] == "attacker" for g in games)
        rows.append(
            {
                "search": search,
                "games": len(games),
                "found": len(found),
                "median_time_to_find": _median(found),
                "mean_time_to_find": round(statistics.fmean(found), 2) if found else None,
                "attacker_wins": wins,
                "attacker_win_rate": round(wins / len(games), 3),
                "win_rate_95": _interval(wins, len(games)),
            }
        )
    return rows


def wilson(successes: int, trials: int) -> tuple[float, float]:
    """The 95 % Wilson score interval of a rate: games are chaotic enough
    that a different network draw turns many of them, so a rate from 50
    games is only good to about +-14 %, from 200 to about +-7 %."""
    from scipy.stats import binomtest

    interval = binomtest(successes, trials).proportion_ci(confidence_level=0.95, method="wilson")
    return float(interval.low), float(interval.high)


def _interval(successes: int, trials: int) -> list[float]:
    return [round(x, 3) for x in wilson(successes, trials)]


def _group_order(key: tuple) -> tuple:
    """Scenario, then profile from the least impaired, then the labels."""
    scenario, netem, *rest = key
    return (str(scenario), PROFILES.index(netem) if netem in PROFILES else len(PROFILES), str(netem)) + tuple(
        map(_in_order, rest)
    )


def _in_order(label) -> tuple:
    """Numbers before names before None, numbers by value."""
    if isinstance(label, (int, float)) and not isinstance(label, bool):
        return (0, label, "")
    return (1, 0, str(label)) if label is not None else (2, 0, "")


def _median(values: list[float]) -> float | None:
    return round(statistics.median(values), 2) if values else None
