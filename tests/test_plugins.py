"""Behaviours of one's own: found by file, module or entry point, read with
their own options, refused in one sentence when they cannot be had, held by
their guard when they misbehave, and played unchanged by every runtime.

The class and the scenario table are the ones the "Your own agents" page
shows, read from it, and the commands are a user's, run in a folder
outside the checkout."""

from __future__ import annotations

import ast
import json
import math
import os
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

from bearcat.agents.ground_station.guidance.method import GUIDANCE_METHODS
from bearcat.agents.ground_station.tasking import TASKING
from bearcat.agents.guard import Guard
from bearcat.agents.human.behaviour import BEHAVIOURS, direction_problem
from bearcat.runtime.simulate import simulate
from bearcat.scenarios.game import GAMES
from bearcat.scenarios.schema import ScenarioError, parse_scenario
from bearcat.suites.checker import check_run
from tests.support.scenario_files import scenario_text
from tests.support.users import bearcat, install_tactics

pytestmark = pytest.mark.xdist_group("plugins")  # the example package is installed once, for the module

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "your-own-agents.md"


def page_block(language: str) -> str:
    """The first ``language`` code block of the docs page."""
    found = re.search(rf"```{language}\n(.*?)```", PAGE.read_text(), re.S)
    assert found is not None, f"the page has no {language} block"
    return found.group(1)


def with_attacker(table: str, **kw) -> str:
    """The test game (the fake-out on a 21-point grid) with ``table`` as its attacker."""
    text = scenario_text(**kw)
    start = text.index("[[agent]]")
    return text[:start] + table + "\n" + text[text.index("[[agent]]", start + 1) :]


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A user's folder: the page's class in ``sidestep.py`` and the page's table in a copy of the fake-out."""
    where = tmp_path_factory.mktemp("mine")
    (where / "sidestep.py").write_text(page_block("python"))
    (where / "mine.toml").write_text(with_attacker(page_block("toml"), time_limit=20.0, netem="ideal"))
    return where


@pytest.fixture(scope="module")
def tactics(tmp_path_factory) -> Path:
    return install_tactics(tmp_path_factory.mktemp("site"))


# ---------------------------------------------------------------- finding them


def test_the_docs_class_loads_from_its_file_with_its_options(folder):
    checked = bearcat("plugins", "check", "mine.toml", cwd=folder)
    assert checked.returncode == 0, checked.stderr
    assert checked.stdout.startswith("scenario: game ctf [bearcat] with its rules {'capture_radius': 2.5")
    assert (
        "attacker: behaviour sidestep.py:Sidestep [sidestep.py] with {'reach': 10.0, 'angle': 60.0}: loads"
        in checked.stdout
    )
    scenario = parse_scenario((folder / "mine.toml").read_text(), directory=folder)
    chosen = scenario.behaviour_of("attacker")
    assert type(chosen.options).__name__ == "Options" and chosen.options.reach == 10.0
    # The run keeps the scenario naming the file by its absolute path, which any folder reads.
    assert f'behaviour = "{folder / "sidestep.py"}:Sidestep"' in scenario.text
    again = parse_scenario(scenario.text, directory=Path("/"))
    assert again.behaviour_of("attacker").entry.factory is chosen.entry.factory


def test_a_module_on_the_path_is_named_module_colon_attribute(tmp_path, monkeypatch):
    (tmp_path / "mytactics_on_path.py").write_text(page_block("python"))
    monkeypatch.syspath_prepend(str(tmp_path))
    entry = BEHAVIOURS.get("mytactics_on_path:Sidestep")
    assert entry.origin == "mytactics_on_path" and entry.options_type().reach == 8.0
    assert entry.summary == "Run home; while the defender is shown within reach, step across its line."


def test_an_installed_distribution_registers_a_short_name(tactics, folder):
    listed = bearcat("plugins", "list", "--json", cwd=folder, env={"PYTHONPATH": str(tactics)})
    assert listed.returncode == 0, listed.stderr
    entries = {e["name"]: e for e in json.loads(listed.stdout)["entries"]}
    assert {"fake-out", "go-no-go", "direct", "keyboard"} <= set(entries)
    mine = entries["near-feint"]
    assert mine["origin"].startswith("distribution bearcat-tactics") and mine["traits"] == ["commits", "events"]
    assert entries["fake-out"]["origin"] == "bearcat"


BROKEN = {
    "raises_on_import.py": "raise ZeroDivisionError('at import')\n",
    "not_a_behaviour.py": "class Plain:\n    def decide(self, *a):\n        return None\n",
    "odd_trait.py": (
        "from bearcat.plugins import Behaviour\n"
        "class Odd(Behaviour):\n    traits = frozenset({'flies'})\n"
        "    def decide(self, *a):\n        return None\n"
    ),
}


@pytest.mark.parametrize(
    "behaviour, options, said",
    [
        ("sidestepp", "", "agent[0].behaviour: there is no behaviour 'sidestepp'; the behaviours are follow-guidance"),
        (
            "no_such_module_xyz:Thing",
            "",
            "agent[0].behaviour: 'no_such_module_xyz:Thing': module no_such_module_xyz cannot be imported: "
            "ModuleNotFoundError: No module named 'no_such_module_xyz'",
        ),
        ("sidestep.py:Sidestepp", "", "agent[0].behaviour: 'sidestep.py:Sidestepp': sidestep.py has no attribute"),
        ("elsewhere.py:Sidestep", "", "agent[0].behaviour: 'elsewhere.py:Sidestep': there is no file"),
        ("raises_on_import.py:X", "", "raises_on_import.py raised ZeroDivisionError: at import"),
        ("just_a_name:", "", "agent[0].behaviour: 'just_a_name:' is not a name nor module:attribute"),
        (
            "not_a_behaviour.py:Plain",
            "",
            "agent[0].behaviour: 'not_a_behaviour.py:Plain' is the class bearcat_plugin_not_a_behaviour",
        ),
        (
            "odd_trait.py:Odd",
            "",
            "'odd_trait.py:Odd' declares trait 'flies'; a behaviour's traits are commits, events, keys",
        ),
        (
            "sidestep.py:Sidestep",
            "options = { reech = 3.0 }",
            "agent[0].options: unknown key 'reech'; the keys there are reach, angle",
        ),
        (
            "sidestep.py:Sidestep",
            'options = { reach = "far" }',
            "agent[0].options.reach: must be a number in [0, 1000] m, got 'far'",
        ),
    ],
)
def test_a_plugin_that_cannot_be_had_stops_the_run_in_one_sentence(folder, behaviour, options, said):
    for name, text in BROKEN.items():
        (folder / name).write_text(text)
    table = '[[agent]]\nid = "attacker"\nteam = "attacker"\nstart = [25.0, 22.0]\nspeed = 3.0\n'
    table += f'behaviour = "{behaviour}"\n{options}\n'
    (folder / "bad.toml").write_text(with_attacker(table))
    with pytest.raises(ScenarioError) as error:
        parse_scenario((folder / "bad.toml").read_text(), source="bad.toml", directory=folder)
    assert said in str(error.value) and "\n" not in str(error.value)


def test_the_command_line_says_the_sentence_and_exits_2(folder):
    """What ``parse_scenario`` refuses, a command prints as its one line of error, before anything starts."""
    (folder / "bad.toml").write_text(with_attacker(_table("no_such_module_xyz:Thing")))
    ran = bearcat("simulate", "bad.toml", cwd=folder)
    assert ran.returncode == 2 and ran.stderr.startswith("bearcat: error: bad.toml: agent[0].behaviour: ")
    assert ran.stderr.strip().endswith("No module named 'no_such_module_xyz'")
    assert len(ran.stderr.strip().splitlines()) == 1, ran.stderr


def test_an_entry_point_that_fails_to_load_is_named_with_its_distribution(tmp_path):
    site = tmp_path / "site"
    info = site / "broken_tactics-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: broken-tactics\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[bearcat.behaviours]\nbroken = broken_tactics_gone:Broken\n")
    listed = bearcat("plugins", "list", cwd=tmp_path, env={"PYTHONPATH": str(site)})
    assert listed.returncode == 1
    assert (
        "behaviour        cannot be used: behaviour 'broken' that distribution broken-tactics registers as "
        "broken_tactics_gone:Broken cannot be loaded: ModuleNotFoundError: No module named 'broken_tactics_gone'"
    ) in listed.stdout
    (tmp_path / "game.toml").write_text(with_attacker(_table("broken")))
    ran = bearcat("simulate", "game.toml", cwd=tmp_path, env={"PYTHONPATH": str(site)})
    assert ran.returncode == 2 and "cannot be loaded: ModuleNotFoundError" in ran.stderr


def _table(behaviour: str, options: str = "") -> str:
    return (
        f'[[agent]]\nid = "attacker"\nteam = "attacker"\nstart = [25.0, 22.0]\nspeed = 3.0\n'
        f'behaviour = "{behaviour}"\naided = true\n{options}\n'
    )


@pytest.mark.parametrize(
    "registry, about",
    [
        (BEHAVIOURS, "behaviour"),
        (GUIDANCE_METHODS, "guidance|method|uncertain|robust|calibrat"),
        (TASKING, "search|strateg|polic"),
        (GAMES, "game"),
    ],
    ids=["behaviours", "guidance", "tasking", "games"],
)
def test_no_plugins_name_is_compared_outside_its_registry(registry, about):
    """A plug-in is reached through its entry and its declared traits,
    never by comparing its name with a string."""
    names = set(registry.names())
    found = []
    for path in (ROOT / "bearcat").rglob("*.py"):
        if path.name == f"{registry.builtins.rsplit('.', 1)[1]}.py":  # the built-ins' own table
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Compare) and re.search(about, ast.unparse(node), re.I):
                for side in [node.left, *node.comparators]:
                    values = side.elts if isinstance(side, ast.Tuple | ast.List | ast.Set) else [side]
                    for value in values:
                        if isinstance(value, ast.Constant) and value.value in names:
                            found.append(f"{path.relative_to(ROOT)}:{node.lineno} compares with {value.value!r}")
    assert found == []


# ---------------------------------------------------------------- the guard


class Ticking:
    """A clock that advances ``step`` seconds each time it is read."""

    def __init__(self, step: float) -> None:
        self.now, self.step = 0.0, step

    def __call__(self) -> float:
        self.now += self.step
        return self.now


def test_the_guard_gives_the_fallback_for_an_exception_a_wrong_answer_and_an_overrun():
    guard = Guard("attacker", "mine", budget=0.025, clock=Ticking(0.010))
    east = np.array([1.0, 0.0])
    assert guard.call(0.1, lambda: east, check=direction_problem) is east  # the first call is free of the budget
    assert guard.call(0.2, lambda: east, check=direction_problem) is east  # 10 ms: within 25 ms
    slow = Guard("attacker", "mine", budget=0.025, clock=Ticking(0.030))
    slow.call(0.0, lambda: east, check=direction_problem)
    assert slow.call(0.1, lambda: east, check=direction_problem) is None
    assert guard.call(0.3, lambda: 1 / 0, check=direction_problem) is None
    for wrong in ("north", [float("nan"), 1.0], [1.0, 2.0, 3.0], {"east": 1}):
        assert guard.call(0.4, lambda wrong=wrong: wrong, check=direction_problem) is None
    assert guard.call(0.5, lambda: None, check=direction_problem) is None  # standing is an answer, not a fault
    assert dict(guard.counts) == {"raised": 1, "returned": 4}
    assert slow.faults[0].sentence() == "attacker: plug-in mine took 30 ms, past its budget of 25 ms"
    assert guard.faults[0].sentence() == "attacker: plug-in mine raised ZeroDivisionError: division by zero"
    assert [f.detail for f in guard.faults[1:3]] == [
        "returned 'north', not a direction (east, north) or None",
        "returned the direction [nan, 1.0], which is not finite",
    ]


UNRULY = '''
import numpy as np

from bearcat.plugins import Behaviour


class Unruly(Behaviour):
    """Runs home, but raises on every 7th call and answers NaN on every 11th."""

    def __init__(self, options, rng):
        self.calls = 0

    def decide(self, now, me, screen, situation):
        self.calls += 1
        if self.calls % 7 == 0:
            raise RuntimeError(f"call {self.calls}")
        if self.calls % 11 == 0:
            return np.array([np.nan, 1.0])
        return situation.navigator.toward(situation.goal, me)


class Stubborn(Behaviour):
    """Raises every time."""

    def decide(self, now, me, screen, situation):
        raise ValueError("no")
'''


def test_a_plugin_that_fails_leaves_its_agent_standing_for_that_tick_and_the_game_goes_on(tmp_path):
    (tmp_path / "unruly.py").write_text(UNRULY)
    text = with_attacker(_table("unruly.py:Stubborn"), netem="ideal", time_limit=10.0)
    scenario = parse_scenario(text, directory=tmp_path)
    start = np.array(scenario.agent("attacker").start)
    moved = []

    def inspect(now, players):
        moved.append(float(np.hypot(*(players.people["attacker"].walker.position - start))))

    outcome = simulate(scenario, inspect=inspect)
    assert outcome.ended and outcome.winner == "defender"  # a standing attacker is caught, or outlasted
    assert max(moved) < 0.5, max(moved)  # it never walked (only the body's sway)
    assert list(outcome.plugin_faults) == ["attacker/unruly.py:Stubborn/raised"]
    assert outcome.plugin_faults["attacker/unruly.py:Stubborn/raised"] > 10


def test_a_simulated_run_records_each_fault_and_the_checker_judges_them(tmp_path):
    (tmp_path / "unruly.py").write_text(UNRULY)
    (tmp_path / "game.toml").write_text(with_attacker(_table("unruly.py:Unruly"), netem="ideal", time_limit=20.0))
    ran = bearcat("simulate", "game.toml", "--out", "runs", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    run = tmp_path / "runs" / "seed-3"
    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    faults = [e for e in events if e["event"] == "plugin"]
    kinds = {e["fault"] for e in faults}
    assert kinds == {"raised", "returned"} and all(e["agent"] == "attacker" for e in faults)
    assert faults[0]["detail"] == "raised RuntimeError: call 7" and faults[0]["plugin"] == "unruly.py:Unruly"
    outcome = json.loads((run / "outcome.json").read_text())
    assert sum(outcome["plugin_faults"].values()) == len(faults)
    findings = {f.name: f for f in check_run(run)}
    assert findings["plugins"].held is True
    assert "attacker's unruly.py:Unruly raised" in findings["plugins"].evidence
    assert "each peer went on, and the game to its verdict" in findings["plugins"].evidence


# ---------------------------------------------------------------- every runtime


SLOW = '''
import time

from bearcat.plugins import Behaviour


class Slow(Behaviour):
    """Runs home; raises on its 5th call and sleeps past its budget on its 10th, early in any game."""

    def __init__(self, options, rng):
        self.calls = 0

    def decide(self, now, me, screen, situation):
        self.calls += 1
        if self.calls == 5:
            raise RuntimeError("fifth")
        if self.calls == 10:
            time.sleep(0.2)
        return situation.navigator.toward(situation.goal, me)
'''


def test_a_live_run_plays_the_plugin_and_judges_its_faults(tmp_path):
    """Each walker peer imports the plug-in from the path its scenario names;
    a raise and a sleep past the budget are each one logged sentence and a
    recorded event, and the game ends with its verdict."""
    (tmp_path / "slow.py").write_text(SLOW)
    (tmp_path / "game.toml").write_text(with_attacker(_table("slow.py:Slow"), netem="ideal", time_limit=12.0))
    ran = bearcat("run", "game.toml", "--out", "run", cwd=tmp_path)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    run = tmp_path / "run"
    findings = {f.name: f for f in check_run(run)}
    assert {name: f.held for name, f in findings.items()} == {
        "logs": True,
        "reliable": True,
        "verdict": True,
        "detection": None,
        "supervision": None,
        "failsafe": None,
        "plugins": True,
        "leftovers": True,
    }, findings
    faults = [json.loads(line) for line in (run / "peers" / "attacker.jsonl").read_text().splitlines()]
    faults = [e for e in faults if e["event"] == "plugin"]
    assert [e["fault"] for e in faults] == ["raised", "overran"]
    assert faults[1]["detail"].startswith("took ") and faults[1]["detail"].endswith("past its budget of 25 ms")
    log = (run / "peers" / "attacker.log").read_text()
    assert "attacker: plug-in slow.py:Slow raised RuntimeError: fifth (1 time so far)" in log
    assert "attacker: plug-in slow.py:Slow took" in log


def test_the_docs_class_plays_live_under_a_fault_plan_that_waits_for_its_go(folder):
    """The page's class, under a plan that pauses the ground station for a
    second once the game is running: the run, the plan and the checker take
    the user's class as they take a built-in."""
    (folder / "plan.toml").write_text(
        '[[fault]]\nkind = "pause"\ntarget = "gs"\nafter = "start"\nat = 2.0\nduration = 1.0\n'
    )
    ran = bearcat("run", "mine.toml", "--faults", "plan.toml", "--out", "faulted", cwd=folder)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    findings = {f.name: f.held for f in check_run(folder / "faulted")}
    assert findings["verdict"] and findings["plugins"] and findings["leftovers"], findings
    outcome = json.loads((folder / "faulted" / "outcome.json").read_text())
    assert outcome["ended"] and [f["kind"] for f in outcome["faults"]] == ["pause"]


def test_the_docs_class_plays_in_simulate(folder):
    ran = bearcat("simulate", "mine.toml", "--trials", "3", "--json", cwd=folder)
    assert ran.returncode == 0, ran.stderr
    games = [json.loads(line) for line in ran.stdout.splitlines() if line.startswith("{")]
    assert len([g for g in games if "seed" in g]) == 3


def test_an_installed_plugin_plays_a_20_game_study_against_the_builtin_defender(tactics, tmp_path):
    study = ("study", "holding", "--trials", "20", "--netem", "wifi", "--rate", "1", "--guidance", "plain")
    varied = ("--vary", 'agent.attacker.behaviour="near-feint"', "--vary", "agent.attacker.options={ near = 12.0 }")
    ran = bearcat(*study, *varied, "--out", "mine", "--json", cwd=tmp_path, env={"PYTHONPATH": str(tactics)})
    assert ran.returncode == 0, ran.stderr
    results = [json.loads(line) for line in (tmp_path / "mine" / "results.jsonl").read_text().splitlines()]
    assert len(results) == 20 and all("near-feint" in r["key"] for r in results)
    went = [r for r in results if r["went_at"] is not None]  # the plug-in's commits reach the study's table
    assert went and all(r["went_at"] >= 0 for r in went)
    without = bearcat(*study, *varied, "--out", "other", cwd=tmp_path)  # no PYTHONPATH: not installed here
    assert without.returncode == 2 and "there is no behaviour 'near-feint'" in without.stderr


def test_a_study_change_that_names_a_file_is_read_relative_to_the_folder_it_was_given_in(tmp_path):
    from bearcat.cli.arguments import change

    os.chdir(tmp_path)
    try:
        assert change('agent.attacker.behaviour="mine.py:Mine"') == (
            "agent.attacker.behaviour",
            f"{tmp_path}/mine.py:Mine",
        )
        assert change("agent.*.fix_rate=5.0") == ("agent.*.fix_rate", 5.0)
        assert change("agent.defender.options={ standoff = 3.0 }") == ("agent.defender.options", {"standoff": 3.0})
    finally:
        os.chdir(ROOT)


def test_pages_text_matches_what_the_commands_print(folder):
    """The page quotes ``plugins check``; it is what the command prints."""
    quoted = textwrap.dedent(PAGE.read_text().split("$ bearcat plugins check mine.toml\n")[1].split("```")[0])
    checked = bearcat("plugins", "check", "mine.toml", cwd=folder)
    assert checked.stdout == quoted


# ---------------------------------------------------------------- UAV tasking

CORNERS = '''
from bearcat.plugins import Distance, Options, TaskingPolicy


class Corners(TaskingPolicy):
    """Fly between two corners of the map, ``inset`` metres in; fail on every third call."""

    class Options(Options, frozen=True):
        inset: Distance = 20.0

    def __init__(self, options, rng):
        self.inset, self.calls = options.inset, 0

    def next_point(self, uav, view):
        self.calls += 1
        if self.calls % 3 == 0:
            raise RuntimeError("third")
        xmin, ymin, xmax, ymax = view.map.bounds
        x = xmin + self.inset if self.calls % 2 else xmax - self.inset
        return (x, ymax - self.inset), None
'''


def search_with(tmp_path, policy: str, options: str = "") -> Path:
    """The search scenario, its UAV tasked by ``policy``."""
    text = (ROOT / "bearcat" / "scenarios" / "data" / "search.toml").read_text()
    text = text.replace('search = "reachability"', f'search = "{policy}"\n{options}').replace("240.0", "30.0")
    (tmp_path / "search.toml").write_text(text)
    return tmp_path / "search.toml"


def test_a_tasking_policy_of_ones_own_flies_the_uav_and_its_faults_keep_the_last_task(tmp_path):
    from bearcat.agents.ground_station.event_log import read_events
    from bearcat.scenarios.schema import load_scenario

    (tmp_path / "corners.py").write_text(CORNERS)
    scenario = load_scenario(search_with(tmp_path, "corners.py:Corners", "search_options = { inset = 30.0 }"))
    assert scenario.tasking_of("q1").options.inset == 30.0
    outcome = simulate(scenario, events=tmp_path / "events.jsonl")
    assert outcome.ended
    events = read_events(tmp_path / "events.jsonl")
    tasks = [e["message"] for e in events if e["event"] == "sent" and "/task" in e["key"]]
    searching = [m for m in tasks if m["t"] < outcome.notes.get("search.found_at", math.inf)]  # then it tracks
    places = {tuple(round(v) for v in scenario.map.to_local(m["lat"], m["lon"])) for m in searching}
    xmin, _, xmax, ymax = scenario.map.bounds
    assert places <= {(round(xmin + 30), round(ymax - 30)), (round(xmax - 30), round(ymax - 30))}, places
    faults = [e for e in events if e["event"] == "plugin"]
    assert faults and all(e["agent"] == "uav-tasking" and e["fault"] == "raised" for e in faults)
    assert {e["peer"] for e in faults} == {"uav-tasking"}  # simulation gives each ground agent a session
    # A failed second keeps the UAV on its last task: tasks go out every second regardless.
    seconds = sorted({round(m["t"]) for m in tasks})
    assert len(seconds) >= len({round(e["at"]) for e in faults}) and len(tasks) >= 0.9 * (seconds[-1] - seconds[0])


def test_a_tasking_policy_that_answers_garbage_is_refused_for_that_second(tmp_path):
    from bearcat.agents.ground_station.tasking import point_problem
    from bearcat.maps import load_map

    problem = point_problem(load_map("campus-250x200"))
    assert problem(None) is None and problem(((10.0, 10.0), None)) is None and problem(((10.0, 10.0), 2)) is None
    assert problem((10.0, 10.0)) == "returned (10.0, 10.0), not (point, tier) or None with the point (east, north)"
    assert problem(((float("nan"), 1.0), None)) == "returned the point (nan, 1.0), which is not finite"
    assert problem(((1e6, 1.0), None)) == "returned the point (1e+06, 1), off map campus-250x200"
    assert problem(((1.0, 1.0), "top")) == "returned the tier 'top', not an integer or None"


def test_an_installed_tasking_policy_plays_by_its_short_name(tactics, tmp_path):
    listed = bearcat("plugins", "list", "--json", cwd=tmp_path, env={"PYTHONPATH": str(tactics)})
    entries = {(e["kind"], e["name"]): e for e in json.loads(listed.stdout)["entries"]}
    assert entries["tasking policy", "escort"]["origin"].startswith("distribution bearcat-tactics")
    search_with(tmp_path, "escort")
    checked = bearcat("plugins", "check", "search.toml", cwd=tmp_path, env={"PYTHONPATH": str(tactics)})
    assert checked.returncode == 0 and "q1: tasking policy escort [distribution bearcat-tactics" in checked.stdout
    ran = bearcat("simulate", "search.toml", "--json", cwd=tmp_path, env={"PYTHONPATH": str(tactics)})
    assert ran.returncode == 0, ran.stderr
    game = json.loads(ran.stdout.splitlines()[0])
    assert game["plugin_faults"] == {} and game["reason"]


def test_the_examples_escort_plays_a_20_game_study_and_a_fault_plan(tactics, tmp_path, monkeypatch, bearcat_simulate):
    """Against the built-in defender: 20 games of the search study (a minute
    each), then one under a plan that pauses the ground station."""
    study = ("study", "search", "--trials", "20", "--search", "escort", "--vary", "scenario.time_limit=60.0")
    ran = bearcat(*study, "--out", "escort", "--json", cwd=tmp_path, env={"PYTHONPATH": str(tactics)})
    assert ran.returncode == 0, ran.stderr
    (row,) = json.loads(ran.stdout)
    assert row["search"] == "escort" and row["games"] == 20
    results = [json.loads(line) for line in (tmp_path / "escort" / "results.jsonl").read_text().splitlines()]
    assert len(results) == 20 and all("search=escort" in r["key"] and r["reason"] for r in results)
    monkeypatch.syspath_prepend(str(tactics))
    path = search_with(tmp_path, "bearcat_tactics.escort:Escort")
    run = bearcat_simulate(path, [{"kind": "pause", "target": "gs", "at": 5.0, "duration": 2.0}])
    run.assert_held()
    assert run.findings["failsafe"].held is None  # back within the UAV's 5 s link timeout: no failsafe was due
    assert run.findings["failsafe"].evidence == "no UAV lost its ground station for longer than its link timeout"


def test_the_pytest_plugins_fixtures_play_the_docs_class_under_a_fault_plan(folder, bearcat_simulate):
    """The fixtures a user's own fault suite gets (``bearcat.suites.plugin``) take the scenario naming the class."""
    run = bearcat_simulate(folder / "mine.toml", [{"kind": "pause", "target": "gs", "at": 2.0, "duration": 1.0}])
    run.assert_held()
    assert run.outcome["ended"] and [f["kind"] for f in run.outcome["faults"]] == ["pause"]
    assert run.held("plugins") is True


# ---------------------------------------------------------------- games

KEEPAWAY = '''
import dataclasses

from bearcat.plugins import GAMES

Pursuit = GAMES.get("pursuit").factory


class Keepaway(Pursuit):
    """Pursuit whose rules also say how long the evader must last, which this game takes as its time limit."""

    class Options(Pursuit.Options, frozen=True):
        last: float = 15.0

    def __init__(self, scenario, **kw):
        super().__init__(scenario, **kw)
        self.lasting = self.table.last

    def referee(self, on_truth=True):
        made = super().referee(on_truth)
        made.contest = dataclasses.replace(made.contest, time_limit=self.lasting)
        return made
'''


def test_a_game_of_ones_own_reads_its_rules_and_plays(tmp_path):
    """A game is found as any plug-in is: its rules type reads the scenario's
    ``[rules]`` (a key the built-in's has not, refused by the built-in), and
    the game it makes is the one played."""
    (tmp_path / "keepaway.py").write_text(KEEPAWAY)
    text = (ROOT / "bearcat" / "scenarios" / "data" / "pursuit-field.toml").read_text()
    text = text.replace('game = "pursuit"', 'game = "keepaway.py:Keepaway"').replace(
        "capture_radius = 2.0", "capture_radius = 2.0\nlast = 12.0"
    )
    scenario = parse_scenario(text, directory=tmp_path)
    assert scenario.game_entry.name == "keepaway.py:Keepaway" and scenario.rules.last == 12.0
    outcome = simulate(scenario)
    assert outcome.ended and outcome.elapsed <= 12.0 + 0.2, outcome  # the game's own limit, not the scenario's 120 s
    with pytest.raises(ScenarioError, match=r"rules: unknown key 'last'; the keys there are capture_radius"):
        parse_scenario(text.replace('game = "keepaway.py:Keepaway"', 'game = "pursuit"'))
    with pytest.raises(ScenarioError, match=r"scenario.game: there is no game 'keepaway'; the games are ctf, "):
        parse_scenario(text.replace('game = "keepaway.py:Keepaway"', 'game = "keepaway"'))
