"""Scenario files: the built-in ones load, and every mistake is one sentence
naming the file and the key."""

import pytest

from bearcat.scenarios.schema import ScenarioError, list_scenarios, load_scenario, parse_scenario
from tests.support.scenario_files import scenario_text


@pytest.mark.parametrize("name", list_scenarios())
def test_every_built_in_scenario_loads(name):
    scenario = load_scenario(name)
    assert scenario.name == name and scenario.agents and scenario.time_limit > 0


def test_the_studies_scenarios_are_built_in():
    assert {"fake-out", "fake-out-aided-defender", "go-no-go"} <= set(list_scenarios())


@pytest.mark.parametrize(
    "change, culprit",
    [
        (('behaviour = "fake-out"', 'behaviour = "fakeout"'), "agent[0].behaviour 'fakeout' is not one of"),
        (("speed = 3.0", "sped = 3.0"), "agent[0].sped is not a known key"),
        (('map = "field-50"', 'map = "field-5"'), "scenario.map: there is no built-in map 'field-5'"),
        (('netem = "wifi"', 'netem = "lte"'), "scenario.netem: there is no netem profile 'lte'"),
        (("grid = 21", "grid = 4"), "rules.grid must be an integer from 9 to 201"),
        (('stages = "return"', 'stages = "flag"'), "rules.stages 'flag' is not one of"),
        (("time_limit = 30.0", "time_limit = -1.0"), "scenario.time_limit must be positive"),
        (('id = "defender"', 'id = "attacker"'), "agent id 'attacker' is used twice"),
        (('team = "defender"', 'team = "attacker"'), "needs at least one agent of team 'defender'"),
        (("start = [25.0, 22.0]", "start = [25.0, 99.0]"), "agent[0].start at (25.0, 99.0) is outside the area"),
        (("start = [25.0, 22.0]", "start = [25.0]"), "agent[0].start must be [east, north]"),
        (('name = "test-game"', 'name = "a game"'), "scenario.name 'a game' must be"),
        (("[rules]", "[rulez]"), "rulez is not a known key"),
    ],
)
def test_a_mistake_names_the_file_and_the_key(change, culprit):
    text = scenario_text().replace(*change, 1)
    with pytest.raises(ScenarioError) as error:
        parse_scenario(text, source="game.toml")
    assert str(error.value).startswith("game.toml: ") and culprit in str(error.value)


def test_options_of_a_behaviour_are_checked():
    text = scenario_text(attacker_behaviour="go-no-go")
    with pytest.raises(ScenarioError, match=r"agent\[0\].options.hold is required by behaviour 'go-no-go'"):
        parse_scenario(text, source="game.toml")
    text = text.replace("aided = true", "aided = true\noptions = { hold = [20.0, 20.0], wait = 3 }", 1)
    with pytest.raises(ScenarioError, match=r"agent\[0\].options.wait is not a known key"):
        parse_scenario(text, source="game.toml")


def test_an_unknown_scenario_is_named(tmp_path):
    with pytest.raises(ScenarioError, match="there is no scenario 'nope'"):
        load_scenario("nope")
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario\\n")
    with pytest.raises(ScenarioError, match=r"bad\.toml is not valid TOML"):
        load_scenario(bad)


def test_study_summaries_count_goes_false_goes_and_real_windows():
    from bearcat.scenarios.studies import study_tasks, summarise

    rows = [
        {"scenario": "s", "netem": "wifi", "winner": "attacker", "went_at": 3.0, "true_value": -0.5},
        {"scenario": "s", "netem": "wifi", "winner": "defender", "went_at": 4.0, "true_value": 0.7},
        {"scenario": "s", "netem": "wifi", "winner": "defender", "went_at": 5.0, "true_value": -0.1},
        {"scenario": "s", "netem": "wifi", "winner": "defender", "went_at": None, "true_value": None},
    ]
    (row,) = summarise(rows)
    assert (row["games"], row["attacker_wins"], row["goes"], row["false_goes"]) == (4, 1, 3, 2)
    assert (row["goes_really_open"], row["really_open_won"], row["median_go_time"]) == (2, 1, 4.0)
    assert row["false_go_rate"] == pytest.approx(2 / 3, abs=1e-3)
    tasks = study_tasks("go-no-go", 3, 10, ["ideal", "3g"])
    assert [t["seed"] for t in tasks] == [10, 11, 12] * 2 and len({t["key"] for t in tasks}) == 6


def test_the_wilson_interval_matches_the_textbook_and_stays_in_zero_one():
    from bearcat.scenarios.studies import wilson

    low, high = wilson(32, 50)
    assert (round(low, 3), round(high, 3)) == (0.501, 0.759)  # p = 0.64, n = 50
    assert wilson(0, 10)[0] == 0.0 and wilson(10, 10)[1] == 1.0
    assert wilson(0, 10)[1] == pytest.approx(0.2775, abs=1e-4)
