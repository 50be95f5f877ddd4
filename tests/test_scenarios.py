"""Scenario files: the built-in ones load, and every mistake is one sentence
naming the file and the key."""

import json
import re

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
        (
            ('behaviour = "fake-out"', 'behaviour = "fakeout"'),
            "agent[0].behaviour: there is no behaviour 'fakeout'; the behaviours are follow-guidance, direct, "
            "fake-out, go-no-go, waypoints, patrol, keyboard, or name one of your own as module:attribute",
        ),
        (
            ("speed = 3.0", "sped = 3.0"),
            "agent[0]: unknown key 'sped'; the keys there are id, team, start, speed, behaviour",
        ),
        (('map = "field-50"', 'map = "field-5"'), "scenario.map: there is no built-in map 'field-5'"),
        (
            ('netem = "wifi"', 'netem = "lte"'),
            "scenario.netem: 'lte' is not one of '3g', '3g-degraded', 'ideal', 'wifi'",
        ),
        (("grid = 21", "grid = 4"), "rules.grid: must be an integer from 9 to 201, got 4"),
        (('stages = "return"', 'stages = "flag"'), "rules.stages: 'flag' is not one of 'both', 'return'"),
        (("time_limit = 30.0", "time_limit = -1.0"), "scenario.time_limit: must be a number in (0, 86400] s, got -1.0"),
        (('id = "defender"', 'id = "attacker"'), "agent id 'attacker' is used twice"),
        (('team = "defender"', 'team = "attacker"'), "needs at least one agent of team 'defender'"),
        (
            ('team = "defender"', 'team = "pursuer"'),
            "agent[1].team: 'pursuer' is not one of 'attacker', 'defender' (the teams of a ctf game)",
        ),
        (("start = [25.0, 22.0]", "start = [25.0, 99.0]"), "agent[0].start at (25.0, 99.0) is outside the area"),
        (("start = [25.0, 22.0]", "start = [25.0]"), "agent[0].start: must be [east, north] in metres, got [25.0]"),
        (
            ('name = "test-game"', 'name = "a game"'),
            "scenario.name: must be 1 to 64 letters, digits, '-' or '_', got 'a game'",
        ),
        (("[rules]", "[rulez]"), "unknown key 'rulez'; the keys there are scenario, agent, rules, guidance, uav"),
        (
            ("capture_radius = 2.5", "capture_radious = 2.5"),
            "rules: unknown key 'capture_radious'; the keys there are capture_radius,",
        ),
        (
            ('behaviour = "fake-out"', 'behavior = "fake-out"'),
            "agent[0]: unknown key 'behavior'; the keys there are id, team, start, speed, behaviour",
        ),
    ],
)
def test_a_mistake_names_the_file_and_the_key(change, culprit):
    text = scenario_text().replace(*change, 1)
    with pytest.raises(ScenarioError) as error:
        parse_scenario(text, source="game.toml")
    assert str(error.value).startswith("game.toml: ") and culprit in str(error.value)


@pytest.mark.parametrize(
    "change, culprit",
    [
        # Once a ZeroDivisionError.
        (
            ("capture_radius = 2.5", "capture_radius = 0"),
            "rules.capture_radius: must be a number in (0, 1000] m, got 0",
        ),
        # Once an overflowing solve cached as converged, after which every run crashed.
        (("speed = 3.0", "speed = 1e300"), "agent[0].speed: must be a number in (0, 15] m/s, got 1e+300"),
        # Once a hang of simulate.
        (
            ("[guidance]\n", "[guidance]\nrate = 1e9\n"),
            "guidance.rate: must be a number in [0.01, 50] Hz, got 1000000000.0",
        ),
        # Once a TypeError.
        (("seed = 3", "seed = 3\ndead_zones = 5"), "scenario.dead_zones: must be a list of polygons of [east, north]"),
        (
            ("seed = 3", "seed = 3\ndead_zones = [[[0, 0], [1, 1]]]"),
            "scenario.dead_zones[0]: must be a polygon of at least 3 [east, north] points, got [[0, 0], [1, 1]]",
        ),
        (
            ("seed = 3", "seed = 3\ndead_zones = [[[0, 0], [9, 9], [9, 0], [0, 9]]]"),
            "scenario.dead_zones[0] is not a valid polygon (Self-intersection",
        ),
        (("speed = 3.0", "speed = nan"), "agent[0].speed: must be a number in (0, 15] m/s, got nan"),
        (("speed = 3.0", "speed = true"), "agent[0].speed: must be a number in (0, 15] m/s, got true"),
        (("time_limit = 30.0", "time_limit = inf"), "scenario.time_limit: must be a number in (0, 86400] s, got inf"),
        (("return_time = 60.0", "return_time = 0.0"), "rules.return_time: must be a number in (0, 3600] s, got 0.0"),
        (("seed = 3", "seed = -1"), "scenario.seed: must be an integer of at least 0, got -1"),
        (("aided = true", "aided = true\nfix_rate = 0"), "agent[0].fix_rate: must be a number in [0.01, 50] Hz, got 0"),
        (
            ("aided = true", "aided = true\nreaction = -0.1"),
            "agent[0].reaction: must be a number in [0, 10] s, got -0.1",
        ),
        (
            ("aided = true", "aided = true\nheading_error = 400"),
            "agent[0].heading_error: must be a number in [0, 180] degrees, got 400",
        ),
        (
            ("aided = true", "aided = true\noptions = { turn_every = 0 }"),
            "agent[0].options.turn_every: must be a number in (0, 600] s, got 0",
        ),
        (
            ("aided = false", "aided = false\noptions = { share = 1.5 }"),
            "agent[1].options.share: must be a number in [0, 1], got 1.5",
        ),
        (
            ("start = [25.0, 22.0]", "start = [25.0, inf]"),
            "agent[0].start[1]: must be a number in [-1e7, 1e7] m, got inf",
        ),
    ],
)
def test_every_number_has_its_bounds(change, culprit):
    text = scenario_text().replace(*change, 1)
    assert text != scenario_text()
    with pytest.raises(ScenarioError) as error:
        parse_scenario(text, source="game.toml")
    assert str(error.value).startswith(f"game.toml: {culprit}")


def test_options_of_a_behaviour_are_checked():
    text = scenario_text(attacker_behaviour="go-no-go")
    with pytest.raises(ScenarioError, match=r"agent\[0\].options.hold: must be given, as \[east, north\] in metres$"):
        parse_scenario(text, source="game.toml")
    text = text.replace("aided = true", "aided = true\noptions = { hold = [20.0, 20.0], wait = 3 }", 1)
    with pytest.raises(ScenarioError, match=r"agent\[0\].options: unknown key 'wait'; the keys there are hold, fresh"):
        parse_scenario(text, source="game.toml")


@pytest.mark.parametrize(
    "hold, culprit",
    [
        ("[100.0, 100.0]", "agent[0].options.hold at (100.0, 100.0) is inside obstacle 'hall' of map campus-200"),
        ("[58.0, 300.0]", "agent[0].options.hold at (58.0, 300.0) is outside the area of map campus-200"),
    ],
)
def test_a_hold_point_is_refused_where_a_waypoint_would_be(hold, culprit):
    text = load_scenario("go-no-go").text
    assert "hold = [58.0, 80.0]" in text
    with pytest.raises(ScenarioError) as error:
        parse_scenario(text.replace("hold = [58.0, 80.0]", f"hold = {hold}"), source="go-no-go.toml")
    assert str(error.value) == f"go-no-go.toml: {culprit}"
    waypoint = text.replace("[140.0, 145.0]", hold)
    with pytest.raises(ScenarioError, match=r"agent\[1\].options.points\[1\] at .* of map campus-200"):
        parse_scenario(waypoint, source="go-no-go.toml")


def test_a_spacing_must_make_a_grid_of_the_map():
    text = load_scenario("open-loop").text
    assert "spacing = 2.0" in text
    with pytest.raises(ScenarioError, match=r"^open-loop.toml: rules.spacing: 0.01 m makes \d+ cells across map"):
        parse_scenario(text.replace("spacing = 2.0", "spacing = 0.01"), source="open-loop.toml")


def test_a_file_that_is_not_utf8_or_nests_too_deeply_is_named(tmp_path):
    latin = tmp_path / "latin.toml"
    latin.write_bytes(scenario_text().replace("test-game", "caf\xe9").encode("latin-1"))
    with pytest.raises(ScenarioError, match=rf"^{latin} is not UTF-8 text \(byte \d+ is 0xe9\)$"):
        load_scenario(latin)
    deep = tmp_path / "deep.toml"
    deep.write_text("x = " + "[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(ScenarioError, match=rf"^{deep} nests arrays or tables too deeply to be a scenario$"):
        load_scenario(deep)


def test_an_unknown_scenario_is_named(tmp_path):
    with pytest.raises(ScenarioError, match="there is no scenario 'nope'"):
        load_scenario("nope")
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario\\n")
    with pytest.raises(ScenarioError, match=r"bad\.toml is not valid TOML"):
        load_scenario(bad)


def test_study_summaries_count_goes_false_goes_and_real_windows():
    from bearcat.cli.study import _goes_table
    from bearcat.scenarios.variants import vary
    from bearcat.studies.thesis import study_tasks, summarise

    won, caught, late = "attacker returned the flag", "attacker captured", "time limit of 120 s"
    rows = [
        {"scenario": "s", "netem": "wifi", "winner": "attacker", "went_at": 3.0, "true_value": -0.5, "reason": won},
        {"scenario": "s", "netem": "wifi", "winner": "defender", "went_at": 4.0, "true_value": 0.7, "reason": caught},
        {"scenario": "s", "netem": "wifi", "winner": "defender", "went_at": 5.0, "true_value": -0.1, "reason": late},
        {"scenario": "s", "netem": "wifi", "winner": "defender", "went_at": None, "true_value": None, "reason": caught},
    ]
    (row,) = summarise(rows)
    assert (row["games"], row["attacker_wins"], row["goes"], row["false_goes"]) == (4, 1, 3, 2)
    # A false go ends caught or out of time; a game without a go counts in neither.
    assert (row["false_goes_caught"], row["false_goes_out_of_time"]) == (1, 1)
    # The printed table keeps its columns whatever the length of a guidance's name.
    header, line = _goes_table([dict(row, guidance="calibrated, no calibration")]).splitlines()
    assert line.index("wifi/tcp") == header.index("network")
    assert line.split()[-4:-2] == ["1", "1"] and header.split()[-8:-6] == ["caught", "timed"]
    assert (row["goes_really_open"], row["really_open_won"], row["median_go_time"]) == (2, 1, 4.0)
    assert row["false_go_rate"] == pytest.approx(2 / 3, abs=1e-3)
    tasks = study_tasks("go-no-go", 3, 10, ["ideal", "3g"])  # 4 guidance x 2 profiles x 3 seeds
    assert [t["seed"] for t in tasks] == [10, 11, 12] * 8 and len({t["key"] for t in tasks}) == 24
    calibrated = study_tasks("go-no-go", 3, 10, ["3g"], guidance=["calibrated"])
    assert [t["labels"]["guidance"] for t in calibrated] == ["calibrated"] * 3
    assert {t["key"] for t in calibrated} < {t["key"] for t in tasks}
    # Ablations are played only when asked for by name, each switching off its part.
    assert not any("ablate" in json.dumps(t["changes"]) for t in tasks)
    (ablated,) = study_tasks("go-no-go", 1, 10, ["3g"], guidance=["calibrated, no bias"])
    assert vary(load_scenario("go-no-go"), ablated["changes"]).ablate == ("bias",)


def test_a_study_refuses_guidance_it_does_not_vary_in_one_sentence(capsys):
    from bearcat.cli.main import main

    assert main(["study", "go-no-go", "--guidance", "calibrated, no belief", "--trials", "1"]) == 2
    said = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--guidance 'calibrated, no belief': the go-no-go study has no such cells" in said
    assert "'calibrated, no calibration'" in said
    assert main(["study", "go-no-go", "--rate", "1", "--trials", "1"]) == 2
    assert "the go-no-go study has no such cells; its rates are none" in capsys.readouterr().err


def test_the_fake_out_maps_aided_rows_play_without_its_unaided_ones():
    from bearcat.studies.thesis import study_tasks

    everything = study_tasks("fake-out", 1, 0, ["wifi"])
    aided = study_tasks("fake-out", 1, 0, ["wifi"], guidance=["plain", "calibrated"])
    assert len(everything) == 2 * 5 * (4 + 3)  # rates x reactions x (markings + aided guidance)
    assert len(aided) == 2 * 5 * 2 and {t["scenario"] for t in aided} == {"fake-out-aided-defender"}
    assert {t["labels"]["guidance"] for t in aided} == {"plain", "calibrated"}
    assert {t["key"] for t in aided} < {t["key"] for t in everything}


def test_a_study_plays_only_the_report_rates_asked_for():
    from bearcat.studies.thesis import study_tasks

    tasks = study_tasks("holding", 2, 0, ["wifi"], guidance=["plain", "calibrated"], rates=[1.0, 5.0])
    assert sorted({(t["labels"]["guidance"], t["labels"]["rate"]) for t in tasks}) == [
        ("calibrated", 1.0),
        ("calibrated", 5.0),
        ("plain", 1.0),
        ("plain", 5.0),
    ]
    assert len(tasks) == 8


def test_the_wilson_interval_matches_the_textbook_and_stays_in_zero_one():
    from bearcat.studies.thesis import wilson

    low, high = wilson(32, 50)
    assert (round(low, 3), round(high, 3)) == (0.501, 0.759)  # p = 0.64, n = 50
    assert wilson(0, 10)[0] == 0.0 and wilson(10, 10)[1] == 1.0
    assert wilson(0, 10)[1] == pytest.approx(0.2775, abs=1e-4)


# --- variants: one cell of a study ---


def test_a_variant_changes_the_keys_it_names_and_is_a_scenario_in_every_respect():
    from bearcat.scenarios.schema import parse_scenario
    from bearcat.scenarios.variants import vary

    base = load_scenario("fake-out")
    changed = vary(
        base,
        {
            "guidance.method": "worst-case",
            "agent.*.fix_rate": 5.0,
            "agent.defender.reaction": 1.2,
            "agent.defender.options.standoff": 3.0,
        },
    )
    assert method_of(changed) == "worst-case" and method_of(base) == "none"
    assert [a.fix_rate for a in changed.agents] == [5.0, 5.0]
    assert changed.agent("defender").reaction == 1.2
    assert changed.agent("attacker").reaction == base.agent("attacker").reaction
    assert changed.behaviour_of("defender").options.standoff == 3.0
    assert changed.behaviour_of("defender").options.lead == base.behaviour_of("defender").options.lead
    # Its TOML is what a peer fetching it gets: it reads back as the same scenario.
    again = parse_scenario(changed.text, game_map=changed.map)
    assert again.agents == changed.agents and method_of(again) == "worst-case"
    assert "with guidance.method = 'worst-case'" in changed.source


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"agent.nobody.reaction": 1.0}, "there is no agent 'nobody'; the ids are attacker, defender"),
        ({"uncertainty": "none"}, "names no key"),
        ({"guidance.method": "cautious"}, "guidance.method: there is no guidance method 'cautious'"),
        ({"guidance.uncertainty": "none"}, "guidance.uncertainty: was replaced by guidance.method, which takes"),
        ({"agent.defender.uncertainty": "none"}, "agent[1].uncertainty: was replaced by agent[1].guidance"),
        ({"guidance.robust": True}, "guidance.robust: was replaced by guidance.method"),
        ({"agent.defender.robust": True}, "agent[1].robust: was replaced by agent[1].guidance"),
        ({"guidance.options": {"spread": 1.0}}, "guidance.options"),
        ({"agent.defender.reaction": -1.0}, "agent[1].reaction"),
        ({"guidance.confidence": 1.0}, "guidance.confidence"),
        ({"guidance.ablate": ["hindsight"]}, "guidance.ablate[0]"),
    ],
)
def test_a_bad_change_is_refused_in_one_sentence_naming_the_key(changes, message):
    from bearcat.scenarios.variants import vary

    with pytest.raises(ScenarioError, match=re.escape(message)) as caught:
        vary(load_scenario("fake-out"), changes)
    assert "\n" not in str(caught.value)


def test_new_scenarios_get_their_game_s_best_guidance_and_the_thesis_reproductions_keep_the_thesis_s(tmp_path):
    path = tmp_path / "new.toml"
    path.write_text(scenario_text().replace('[guidance]\nmethod = "none"\n', ""))
    assert "[guidance]" not in path.read_text() and method_of(load_scenario(path)) == "calibrated"
    for name in ("fake-out", "fake-out-aided-defender", "go-no-go", "search", "open-loop", "small-area"):
        assert method_of(load_scenario(name)) == "none", name
    assert method_of(load_scenario("pursuit-field")) == "none"
    from bearcat.scenarios.variants import vary

    one = vary(load_scenario("fake-out"), {"agent.defender.guidance": "calibrated"})
    assert [one.guidance_of(a.id).entry.name for a in one.agents] == ["none", "calibrated"]
    with pytest.raises(
        ScenarioError,
        match=re.escape("guidance method 'calibrated' builds on calibrated answers, which a reach-avoid game does not"),
    ):
        vary(load_scenario("open-loop"), {"guidance.method": "calibrated"})


def method_of(scenario) -> str:
    """The guidance method every agent of ``scenario`` gets."""
    (name,) = {chosen.entry.name for chosen in scenario.guidance.values()}
    return name
