"""The fake-out study's games with a person playing the defender.

Each game is the study's scenario with the defender's walker driven from a
keyboard, unaided (its phone shows positions only, as the defenders of
thesis 3.5.1 had), played live: the launcher starts every other peer and
prints the ``bearcat peer`` command for the person to run in a terminal of
their own, then waits for them. The outcome is appended to the study's
results file under the labels ``defender = "human"``; the human factors
the models vary (marking, reaction) are the person's own, so they are left
open. A game interrupted or never started is not recorded, and the same
command again plays the games still missing.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from bearcat.runtime.launch import launch
from bearcat.scenarios.schema import load_scenario
from bearcat.scenarios.variants import vary
from bearcat.studies.batch import read_results

PLAYS = {"defender": "fake-out"}
"""The scenario a person's side is played in."""


def human_scenario(side: str):
    """The scenario with ``side`` driven from a keyboard, without guidance."""
    changes = {f"agent.{side}.behaviour": "keyboard", f"agent.{side}.options": {}, f"agent.{side}.aided": False}
    return vary(load_scenario(PLAYS[side]), changes)


def play_human_trials(out: Path, side: str, trials: int, seed: int, say=print) -> None:
    """Play seeds ``seed``.. ``seed + trials - 1`` live with a person as ``side``."""
    scenario = human_scenario(side)
    source = out / f"human-{side}.toml"
    source.write_text(scenario.text, encoding="utf-8")
    results = out / "results.jsonl"
    done = read_results(results)
    labels = {"defender": "human", "marking": None, "reaction": None, "rate": scenario.agent(side).fix_rate}
    for s in range(seed, seed + trials):
        key = f"{PLAYS[side]}/own/defender=human/{s}"
        if key in done:
            continue
        say(f"game {s - seed + 1} of {trials} (seed {s}): you are the {side}")
        outcome = launch(scenario, str(source), out / "human" / f"seed-{s}", seed=s, netem=scenario.netem, say=say)
        if not outcome.ended:
            say(f"seed {s} did not finish ({outcome.reason}); it is not recorded")
            return
        say(f"seed {s}: {outcome.winner} wins ({outcome.reason}) after {outcome.elapsed:.1f} s")
        row = {
            "key": key,
            "scenario": PLAYS[side],
            "labels": labels,
            "seed": s,
            "netem": scenario.netem,
            "transport": scenario.transport,
            "winner": outcome.winner,
            "reason": outcome.reason,
            "elapsed": outcome.elapsed,
            "notes": {"run": outcome.out},
            "went_at": None,
            "true_value": None,
            "found_at": None,
        }
        with results.open("a", encoding="utf-8") as sink:
            sink.write(json.dumps(row, separators=(",", ":")) + "\n")
            sink.flush()
            os.fsync(sink.fileno())
