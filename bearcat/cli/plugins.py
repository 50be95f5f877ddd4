"""``bearcat plugins``: what plug-ins there are, and whether a scenario's load.

``list`` shows every registered entry of every kind (the built-ins, then
what installed distributions register under the entry-point groups) with
where it comes from and its summary; an entry point that fails to load is
listed with the sentence saying why, and the exit code is 1.

``check SCENARIO`` reads the scenario, which imports every plug-in it names
(each agent's behaviour and guidance method, each UAV's tasking policy) and reads each one's
options into its type, then makes each plug-in once as a game would, with
the same seeded generator, without playing: exit 0 when all of them load, 2 with one
sentence naming the culprit when the scenario cannot be read, 1 when a
plug-in's factory fails.
"""

from __future__ import annotations

import functools

import msgspec

from bearcat.cli.arguments import Commands
from bearcat.cli.output import Output


def register(commands: Commands) -> None:
    p = commands.add_parser(
        "plugins",
        description="List the behaviours, guidance methods, UAV tasking policies and games, built-in and "
        "installed, that scenarios may name, or check what one names.",
    )
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)
    listing = verbs.add_parser("list", help="every registered plug-in, with where it comes from")
    listing.add_argument("--json", action="store_true", help="print the entries as JSON only")
    listing.set_defaults(run=run_list)
    check = verbs.add_parser("check", help="import and check the plug-ins a scenario names, without playing")
    check.add_argument("scenario", metavar="SCENARIO", help="a built-in scenario name or a scenario TOML file")
    check.add_argument("--json", action="store_true", help="print what was found as JSON only")
    check.set_defaults(run=run_check)


def run_list(args) -> int:
    from bearcat.agents.registry import PluginError
    from bearcat.plugins import REGISTRIES

    out = Output(args.json)
    rows: list[dict] = []
    broken: list[dict] = []
    for registry in REGISTRIES:
        for entry in registry.entries():
            if isinstance(entry, PluginError):
                broken.append({"kind": registry.kind, "error": str(entry)})
                continue
            rows.append(
                {
                    "kind": registry.kind,
                    "name": entry.name,
                    "origin": entry.origin,
                    "traits": sorted(entry.traits),
                    "summary": entry.summary,
                }
            )
    wide = max((len(r["name"]) for r in rows), default=0)
    kinds = max(len(registry.kind) for registry in REGISTRIES)
    for row in rows:
        out.say(f"{row['kind']:<{kinds}}  {row['name']:<{wide}}  {row['summary']}  [{row['origin']}]")
    for failed in broken:
        out.say(f"{failed['kind']:<{kinds}}  cannot be used: {failed['error']}")
    out.json({"entries": rows, "broken": broken})
    return 1 if broken else 0


def run_check(args) -> int:
    from bearcat.scenarios.cast import TASKER, stream
    from bearcat.scenarios.schema import load_scenario

    scenario = load_scenario(args.scenario)
    out = Output(args.json)
    game = scenario.game_entry
    found = [_made(out, "scenario", "game", game, scenario.rules, lambda: game.factory(scenario), "its rules ")]
    plugged = [(a.id, "behaviour", scenario.behaviour_of(a.id), a.id, "behaviour") for a in scenario.agents]
    plugged += [
        (a.id, "guidance method", scenario.guidance_of(a.id), a.id, "guidance") for a in scenario.agents if a.aided
    ]
    plugged += [(u.id, "tasking policy", scenario.tasking_of(u.id), TASKER, "tasking") for u in scenario.uavs]
    for who, kind, chosen, drawer, purpose in plugged:
        make = functools.partial(chosen.entry.factory, chosen.options, stream(scenario.seed, drawer, purpose))
        found.append(_made(out, who, kind, chosen.entry, chosen.options, make))
    out.json(found)
    return 0 if all(row["made"] for row in found) else 1


def _made(out: Output, who: str, kind: str, entry, options, make, said: str = "") -> dict[str, object]:
    """``entry`` (for ``who``, with ``options``) made once by ``make()`` as a game makes it, and what came of it."""
    row: dict[str, object] = {
        "for": who,
        "kind": kind,
        "name": entry.name,
        "origin": entry.origin,
        "options": msgspec.to_builtins(options),
        "made": True,
    }
    try:
        make()
    except Exception as exc:
        row["made"] = False
        row["error"] = f"{type(exc).__name__}: {exc}"
    state = "loads" if row["made"] else f"FAILS to be made: {row['error']}"
    out.say(f"{who}: {kind} {entry.name} [{entry.origin}] with {said}{row['options']}: {state}")
    return row
