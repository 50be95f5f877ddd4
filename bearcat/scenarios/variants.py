"""A scenario with some of its keys set otherwise: one cell of a study.

A change names a key by its path in the file, dotted, with an agent or UAV
picked by its id (``*``: every one)::

    guidance.method              = "worst-case"
    agent.defender.reaction      = 0.8
    agent.*.fix_rate             = 5.0
    agent.defender.options       = { standoff = 3.0 }
    uav.*.search                 = "lawnmower"

The changed file is checked like any other, so a variant is a scenario in
every respect: its TOML (``Scenario.text``) is what a peer fetching it gets,
and a bad change is refused in one sentence naming the key.
"""

from __future__ import annotations

import copy
import tomllib

import tomli_w

from bearcat.scenarios.schema import Scenario, ScenarioError, parse_scenario

LISTS = {"agent": "id", "uav": "id"}
"""The arrays of tables whose entries a change picks by id."""


def vary(scenario: Scenario, changes: dict) -> Scenario:
    """``scenario`` with each ``path = value`` of ``changes`` applied."""
    if not changes:
        return scenario
    data = copy.deepcopy(tomllib.loads(scenario.text))
    for path, value in changes.items():
        _set(data, path, value, scenario.source)
    described = ", ".join(f"{path} = {value!r}" for path, value in changes.items())
    return parse_scenario(
        tomli_w.dumps(data),
        source=f"{scenario.source} with {described}",
        game_map=scenario.map,
        directory=scenario.directory,
    )


def _set(data: dict, path: str, value, source: str) -> None:
    parts = path.split(".")
    if len(parts) < 2:
        raise ScenarioError(f"{source}: change {path!r} names no key; write TABLE.KEY, such as guidance.method")
    head, rest = parts[0], parts[1:]
    if head in LISTS:
        if len(rest) < 2:
            raise ScenarioError(f"{source}: change {path!r} needs {head}.ID.KEY, such as {head}.*.fix_rate")
        wanted, rest = rest[0], rest[1:]
        entries = [e for e in data.get(head, ()) if wanted == "*" or e.get(LISTS[head]) == wanted]
        if not entries:
            ids = ", ".join(str(e.get(LISTS[head])) for e in data.get(head, ())) or "none"
            raise ScenarioError(f"{source}: change {path!r}: there is no {head} {wanted!r}; the ids are {ids}")
        for entry in entries:
            _put(entry, rest, value)
    else:
        _put(data.setdefault(head, {}), rest, value)


def _put(table: dict, keys: list[str], value) -> None:
    for key in keys[:-1]:
        table = table.setdefault(key, {})
    table[keys[-1]] = value
