"""Guidance methods of one's own: what an aided phone is told comes from a
user's class, found as any plug-in is, held by its guard when it
misbehaves (that phone shows "no advice" for that moment), shown on the
screen and in the recording, and played unchanged by every runtime; the
example package's ``intercept`` among them."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from bearcat.agents.ground_station.event_log import read_events
from bearcat.agents.ground_station.guidance.method import Advice, advice_problem
from bearcat.scenarios.schema import ScenarioError, load_scenario, parse_scenario
from bearcat.suites.checker import check_run
from tests.support.scenario_files import scenario_text
from tests.support.users import ROOT, bearcat, install_tactics

pytestmark = pytest.mark.xdist_group("guidance-methods")

SHOUT = '''
from msgspec.structs import replace

from bearcat.plugins import Advice, GuidanceMethod, Options


class Shout(GuidanceMethod):
    """The thesis's answer, with a line of its own on the screen."""

    needs = frozenset({"plain"})

    class Options(Options, frozen=True):
        word: str = "hello"

    def __init__(self, options, rng):
        self.word = options.word

    def advise(self, view):
        return replace(view.answers.plain(view), note=f"{self.word} from {view.agent}'s method")


class Unruly(GuidanceMethod):
    """The thesis's answer, but every 7th call raises, every 11th has a NaN
    value, every 13th a heading of 1e9 degrees and every 17th is a string."""

    def __init__(self, options, rng):
        self.calls = 0

    def advise(self, view):
        self.calls += 1
        if self.calls % 7 == 0:
            raise RuntimeError(f"call {self.calls}")
        if self.calls % 11 == 0:
            return Advice(value=float("nan"))
        if self.calls % 13 == 0:
            return Advice(heading=1e9)
        if self.calls % 17 == 0:
            return "north"
        return view.answers.plain(view)


class Slow(GuidanceMethod):
    """The thesis's answer; raises on its 10th call and sleeps past its budget on its 20th, early in any game."""

    def __init__(self, options, rng):
        self.calls = 0

    def advise(self, view):
        import time

        self.calls += 1
        if self.calls == 10:
            raise RuntimeError("tenth")
        if self.calls == 20:
            time.sleep(0.2)
        return view.answers.plain(view)
'''


def game(folder: Path, method: str, options: str = "", **kw) -> Path:
    """The test game (the fake-out on a 21-point grid, both players aided)
    in ``folder``, every phone told by ``method``; its classes in ``mine.py``."""
    (folder / "mine.py").write_text(SHOUT)
    text = scenario_text(defender_behaviour="follow-guidance", defender_aided=True, **kw)
    text = text.replace('method = "none"', f'method = "{method}"\n{options}')
    (folder / "game.toml").write_text(text)
    return folder / "game.toml"


def guidance_to(run: Path, agent: str) -> list[dict]:
    """Every guidance message sent to ``agent`` that the run in ``run`` recorded whole."""
    return [
        e["message"]
        for e in read_events(run / "events.jsonl")
        if e["event"] == "sent" and e.get("message", {}).get("type") == "guidance" and e["message"]["agent"] == agent
    ]


# ---------------------------------------------------------------- naming one


def test_a_method_is_named_with_its_options_per_scenario_and_per_agent(tmp_path):
    path = game(tmp_path, "mine.py:Shout", 'options = { word = "hi" }')
    scenario = load_scenario(path)
    chosen = {agent: scenario.guidance_of(agent) for agent in ("attacker", "defender")}
    assert {agent: (c.entry.name, c.options.word) for agent, c in chosen.items()} == {
        "attacker": ("mine.py:Shout", "hi"),
        "defender": ("mine.py:Shout", "hi"),
    }
    own = path.read_text().replace("aided = true\n\n[[agent]]", 'aided = true\nguidance = "worst-case"\n\n[[agent]]')
    mixed = parse_scenario(own, directory=tmp_path)
    assert [mixed.guidance_of(a).entry.name for a in ("attacker", "defender")] == ["worst-case", "mine.py:Shout"]


@pytest.mark.parametrize(
    "method, options, said",
    [
        ("mine.py:Nope", "", "guidance.method: 'mine.py:Nope': mine.py has no attribute 'Nope'"),
        ("nowhere.py:Shout", "", "guidance.method: 'nowhere.py:Shout': there is no file "),
        ("mine.py:Shout", "options = { word = 3 }", "guidance.options.word: must be a string, got 3"),
        (
            "mine.py:Shout",
            "options = { shout = true }",
            "guidance.options: unknown key 'shout'; the keys there are word",
        ),
        ("intercept", "", "guidance.method: there is no guidance method 'intercept'; the guidance methods are none"),
    ],
)
def test_a_method_that_cannot_be_had_is_refused_in_one_sentence(tmp_path, method, options, said):
    path = game(tmp_path, method, options)
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    assert said in str(caught.value) and "\n" not in str(caught.value)
    ran = bearcat("simulate", "game.toml", cwd=tmp_path)
    assert ran.returncode == 2 and said in ran.stderr


def test_the_advice_check_names_what_the_wire_cannot_carry():
    assert advice_problem(Advice(heading=90.0, value=-1.0, note="fine")) is None
    assert advice_problem("north") == "returned 'north', not an Advice"
    assert advice_problem(Advice(heading=1e9)) == "returned a heading of 1000000000.0 degrees, not one in [0, 360)"
    assert advice_problem(Advice(heading=float("nan"))) == "returned a heading of nan degrees, not one in [0, 360)"
    assert advice_problem(Advice(value=float("inf"))) == "returned advice the wire cannot carry: value must be finite"
    too_long = Advice(note="x" * 201)
    assert advice_problem(too_long).startswith("returned advice the wire cannot carry: Expected `str` of length <= 200")


# ---------------------------------------------------------------- what the phone is told


def test_the_phone_and_the_recording_show_what_a_method_of_ones_own_sends(tmp_path):
    game(tmp_path, "mine.py:Shout", 'options = { word = "hi" }', time_limit=15.0, netem="ideal")
    ran = bearcat("simulate", "game.toml", "--out", "out", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    run = tmp_path / "out" / "seed-3"
    sent = guidance_to(run, "defender")
    assert sent and all(m["note"] == "hi from defender's method" for m in sent if m["game"] == "ctf")
    assert any(m.get("heading") is not None for m in sent)  # the thesis's heading, which it built on
    assert b"phone/defender/note" in (run / "recording.rrd").read_bytes()  # the screen's line, in the recording


def test_a_method_that_fails_shows_no_advice_for_that_moment_and_the_game_goes_on(tmp_path):
    game(tmp_path, "mine.py:Unruly", time_limit=20.0, netem="ideal")
    ran = bearcat("simulate", "game.toml", "--out", "out", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    run = tmp_path / "out" / "seed-3"
    faults = [e for e in read_events(run / "events.jsonl") if e["event"] == "plugin"]
    details = {e["fault"]: set() for e in faults}
    for e in faults:
        details[e["fault"]].add(e["detail"].split(":")[0])
    assert details == {
        "raised": {"raised RuntimeError"},
        "returned": {
            "returned advice the wire cannot carry",
            "returned a heading of 1000000000.0 degrees, not one in [0, 360)",
            "returned 'north', not an Advice",
        },
    }
    assert {e["agent"] for e in faults} == {"attacker", "defender"}
    assert all(e["plugin"] == "mine.py:Unruly" for e in faults)
    for agent in ("attacker", "defender"):
        sent = guidance_to(run, agent)
        told = [m for m in sent if m["game"] == "ctf"]
        blank = [m for m in told if m["note"] == "no advice"]
        assert len(blank) == sum(e["agent"] == agent for e in faults)
        assert all(m.get("heading") is None and m.get("region", []) == [] for m in blank)
        assert len(told) > 2 * len(blank)  # the other moments were answered
    outcome = json.loads((run / "outcome.json").read_text())
    assert outcome["ended"] and sum(outcome["plugin_faults"].values()) == len(faults)
    findings = {f.name: f for f in check_run(run)}
    assert findings["plugins"].held is True and findings["verdict"].held is True
    # A record that lost the game's end (a full disk) cannot say whether each peer went on after its fault;
    # an outcome that never ended says the game had no verdict.
    lines = (run / "events.jsonl").read_text().splitlines(keepends=True)
    (run / "events.jsonl").write_text("".join(line for line in lines if '"phase":"ended"' not in line))
    assert {f.name: f.held for f in check_run(run)}["plugins"] is None
    (run / "outcome.json").write_text(json.dumps(outcome | {"ended": False}))
    assert {f.name: f.held for f in check_run(run)}["plugins"] is False


# ---------------------------------------------------------------- the example package


@pytest.fixture(scope="module")
def tactics(tmp_path_factory) -> Path:
    return install_tactics(tmp_path_factory.mktemp("site"))


def test_the_examples_intercept_steers_the_defender_to_the_cut_off_point_in_simulation_and_live(tactics, tmp_path):
    env = {"PYTHONPATH": str(tactics)}
    listed = bearcat("plugins", "list", "--json", cwd=tmp_path, env=env)
    entries = {(e["kind"], e["name"]): e for e in json.loads(listed.stdout)["entries"]}
    assert entries["guidance method", "intercept"]["origin"].startswith("distribution bearcat-tactics")
    assert entries["guidance method", "intercept"]["traits"] == ["tracks"]
    path = game(tmp_path, "none", time_limit=20.0, netem="ideal")
    text = path.read_text().replace(
        '"follow-guidance"\naided = true', '"follow-guidance"\naided = true\nguidance = "intercept"'
    )
    path.write_text(text)
    ran = bearcat("simulate", "game.toml", "--out", "out", cwd=tmp_path, env=env)
    assert ran.returncode == 0, ran.stderr
    sent = guidance_to(tmp_path / "out" / "seed-3", "defender")
    cut = [m for m in sent if m["note"].startswith("cut off in ")]
    assert len(cut) > len(sent) // 2 and all(0 <= m["heading"] < 360 for m in cut)
    assert not any(m["note"].startswith("cut off") for m in guidance_to(tmp_path / "out" / "seed-3", "attacker"))
    # Live, under a fault plan that pauses the ground station, with the attacker's phone told by a file's
    # method that raises once and sleeps past its budget once: each fault is one logged sentence and a
    # recorded event, the game ends with its verdict, and the checker says so.
    path.write_text(text.replace('method = "none"', 'method = "mine.py:Slow"'))
    (tmp_path / "plan.toml").write_text(
        '[[fault]]\nkind = "pause"\ntarget = "gs"\nafter = "start"\nat = 2.0\nduration = 1.0\n'
    )
    live = bearcat("run", "game.toml", "--faults", "plan.toml", "--out", "live", cwd=tmp_path, env=env)
    assert live.returncode == 0, live.stdout + live.stderr
    here = {f.name: f for f in check_run(tmp_path / "live")}  # this process cannot import intercept
    assert here["verdict"].held is None and "there is no guidance method 'intercept'" in here["verdict"].evidence
    checked = bearcat("check", "live", "--json", cwd=tmp_path, env=env)
    findings = {f["name"]: f["held"] for f in json.loads(checked.stdout)}
    assert findings["verdict"] and findings["plugins"] and findings["leftovers"], findings
    assert any(m["note"].startswith("cut off in ") for m in guidance_to(tmp_path / "live", "defender"))
    faults = [e for e in read_events(tmp_path / "live" / "peers" / "gs.jsonl") if e["event"] == "plugin"]
    # The tenth call raises and the twentieth sleeps 200 ms, eight budgets. The budget is held on the wall
    # clock, so on a busy machine an ordinary call may overrun it too; the guard records that as well.
    assert {e["agent"] for e in faults} == {"attacker"}
    assert [e["fault"] for e in faults if e["fault"] != "overran"] == ["raised"]
    details = [e["detail"] for e in faults if e["fault"] == "overran"]
    overruns = [re.fullmatch(r"took (\d+) ms, past its budget of 25 ms", detail) for detail in details]
    assert all(overruns) and any(int(m[1]) >= 200 for m in overruns if m), details
    log = (tmp_path / "live" / "peers" / "gs.log").read_text()
    assert "attacker: plug-in mine.py:Slow raised RuntimeError: tenth (1 time so far)" in log
    assert "attacker: plug-in mine.py:Slow took" in log


def test_the_examples_intercept_plays_a_20_game_study_against_the_builtin_guidance(tactics, tmp_path):
    study = ("study", "holding", "--trials", "20", "--netem", "wifi", "--rate", "1", "--guidance", "plain")
    ran = bearcat(
        *study, "--vary", 'agent.defender.guidance="intercept"', "--out", "mine", "--json",
        cwd=tmp_path, env={"PYTHONPATH": str(tactics)},
    )  # fmt: skip
    assert ran.returncode == 0, ran.stderr
    results = [json.loads(line) for line in (tmp_path / "mine" / "results.jsonl").read_text().splitlines()]
    assert len(results) == 20 and all("intercept" in r["key"] for r in results)
    assert {r["winner"] for r in results} <= {"attacker", "defender"} and all(r["reason"] for r in results)


def test_the_docs_page_shows_the_examples_method_as_it_is():
    page = (ROOT / "docs" / "your-own-agents.md").read_text()
    shown = page.split("```python\nfrom __future__ import annotations\n")[1].split("```")[0]
    example = (ROOT / "examples" / "bearcat-tactics" / "bearcat_tactics" / "intercept.py").read_text()
    assert example.endswith("from __future__ import annotations\n" + shown)
