"""The limited-visibility game with a UAV (thesis 6.2.4), played in simulation:
P_D against the defender's true track, what each side is told, the UAV's
tasks and detections. The built-in search scenario on a 35-point grid, so
the capture-the-flag solve takes seconds."""

from __future__ import annotations

import math
from dataclasses import replace

import msgspec
import numpy as np
import pytest

from bearcat.agents.ground_station.event_log import read_events
from bearcat.agents.ground_station.uav_tasking import TRACK_FOR
from bearcat.runtime.simulate import simulate
from bearcat.scenarios.schema import ScenarioError, load_scenario, parse_scenario
from tests.support.answers import answering


def _text(**changes) -> str:
    text = load_scenario("search").text.replace("grid = 45", "grid = 35").replace('netem = "3g"', 'netem = "ideal"')
    text = text.replace("time_limit = 240.0", "time_limit = 90.0")
    for old, new in changes.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


@pytest.fixture(scope="module")
def scenario():
    return parse_scenario(_text(), source="search.toml")


@pytest.mark.parametrize("search", ["reachability", "nearest"])
def test_the_possible_set_always_holds_the_defender_while_it_is_unseen(scenario, search):
    """Checked against the truth ten times a second: wherever the defender
    really is, P_D has a node within a cell, plus the metres the defender
    walks in the second a fix may be old (sensing runs on fixes)."""
    scenario = replace(scenario, uavs=tuple(msgspec.structs.replace(u, search=search) for u in scenario.uavs))
    checked, seen_updates = [], {"n": -1}

    def inspect(now, players):
        (tasker,) = players.tasking
        picture = tasker.picture
        if picture.updates == seen_updates["n"] or picture.possible is None:
            return
        seen_updates["n"] = picture.updates
        last = picture.sightings[-1][0] if picture.sightings else -math.inf
        if now - last <= TRACK_FOR + 1.0:
            return  # P_D sits on the sighting
        truth = players.people["defender"].walker.position
        nodes = np.argwhere(picture.possible)
        assert len(nodes), f"P_D is empty at {now:.1f} s while the defender is unseen"
        points = np.asarray(tasker.grid.lo) + nodes * np.asarray(tasker.grid.spacing)
        slack = max(tasker.grid.spacing) * math.sqrt(2) + tasker.defender_speed * 1.0
        gap = float(np.min(np.hypot(*(points - truth).T)))
        assert gap <= slack, f"at {now:.1f} s the defender at {truth.round(1)} is {gap:.1f} m outside P_D"
        checked.append(now)

    simulate(scenario, seed=1, inspect=inspect)
    assert len(checked) >= 10  # the search really ran


def test_the_attacker_is_told_of_the_defender_only_after_its_side_saw_it(scenario, tmp_path):
    for seed in range(6):  # the first game in which the UAV or the attacker finds the defender
        events = tmp_path / f"events-{seed}.jsonl"
        found = simulate(scenario, seed=seed, events=events).notes.get("search.found_at")
        if found is not None:
            break
    assert found is not None, "the defender was never found in six games"
    told = [
        e
        for e in read_events(events)
        if e["event"] == "sent"
        and e["message"].get("type") == "guidance"
        and e["message"]["agent"] == "attacker"
        and any(r["agent"] == "defender" for r in e["message"]["reports"])
    ]
    assert told, "the attacker never learnt where the defender was"
    assert min(e["t"] for e in told) >= found - 1e-9
    everyone = [
        e
        for e in read_events(events)
        if e["event"] == "sent" and e["message"].get("type") == "guidance" and e["message"]["agent"] == "attacker"
    ]
    assert all(e["message"]["game"] == "search" and e["message"]["possible"] for e in everyone[:20])
    assert any(r["agent"] == "q1" for r in everyone[-1]["message"]["reports"])  # its UAV, always


def test_the_uav_climbs_searches_once_a_second_and_its_camera_finds_the_defender(scenario, tmp_path):
    events = tmp_path / "events.jsonl"
    outcome = simulate(scenario, seed=0, events=events)
    log = read_events(events)
    uav_truth = [
        e["message"]
        for e in log
        if e["event"] == "sent" and e["message"].get("type") == "truth" and e["message"]["agent"] == "q1"
    ]
    assert max(m["alt"] for m in uav_truth) == pytest.approx(20.0, abs=0.6)
    tasks = [e["t"] for e in log if e["event"] == "sent" and e["message"].get("type") == "uav-task"]
    assert len(tasks) >= 0.8 * (tasks[-1] - tasks[0]) and np.all(np.diff(tasks) > 0.5)
    detections = [e["message"] for e in log if e["event"] == "sent" and e["message"].get("type") == "detection"]
    if outcome.notes.get("search.found_by") == "q1":
        assert detections and detections[0]["agent"] == "defender"
    for d in detections:  # the camera reported the truth, within r_q of the UAV
        t = next(e["t"] for e in log if e["event"] == "sent" and e["message"] is d)
        near = min((m for m in uav_truth), key=lambda m: abs(m["t"] - t))
        east, north = scenario.map.to_local(d["lat"], d["lon"])
        ue, un = scenario.map.to_local(near["lat"], near["lon"])
        assert math.hypot(east - ue, north - un) <= 15.0 + 1.0


def test_uav_tables_are_checked_key_by_key():
    with pytest.raises(
        ScenarioError,
        match=r"uav\[0\]\.search: there is no tasking policy 'random'; the tasking policies are reachability, "
        r"lawnmower, nearest, or name one of your own as module:attribute$",
    ):
        parse_scenario(_text(**{'search = "reachability"': 'search = "random"'}), source="s.toml")
    with pytest.raises(ScenarioError, match=r"uav\[0\]\.start: \[300.0, 12.0\] is off map campus-250x200"):
        parse_scenario(_text(**{"start = [125.0, 12.0]": "start = [300.0, 12.0]"}), source="s.toml")
    with pytest.raises(ScenarioError, match=r"uav\[0\]: unknown key 'camera'; the keys there are id, team, start"):
        parse_scenario(_text(**{"camera_radius = 15.0": "camera = 15.0"}), source="s.toml")
    with pytest.raises(ScenarioError, match=r"agent id 'attacker' is used twice"):
        parse_scenario(_text(**{'id = "q1"': 'id = "attacker"'}), source="s.toml")
    with pytest.raises(ScenarioError, match=r"rules.visibility: 'none' is not one of 'full', 'line-of-sight'$"):
        parse_scenario(_text(**{'visibility = "line-of-sight"': 'visibility = "none"'}), source="s.toml")
    with pytest.raises(ScenarioError, match=r"uav\[0\]\.speed: must be a number in \(0, 40\] m/s, got 1e\+300$"):
        parse_scenario(_text(**{"speed = 8.0": "speed = 1e300"}), source="s.toml")
    with pytest.raises(ScenarioError, match=r"uav\[0\]\.altitude: must be a number in \(0, 500\] m, got -5.0$"):
        parse_scenario(_text(**{"altitude = 20.0": "altitude = -5.0"}), source="s.toml")


def test_the_attackers_go_holds_against_every_place_the_defender_may_be(scenario):
    """The phone's value is the worst over P_D: go with P_D in a corner where
    the defender loses, no go once P_D also holds a place where it wins."""
    from bearcat.agents.ground_station.guidance.fixes import LatestFixes
    from bearcat.bus.messages import Fix
    from bearcat.netem.profiles import load_profile
    from bearcat.scenarios.cast import _CtfGame

    game = _CtfGame(scenario)
    advisor = answering(game.guidance(load_profile(scenario.netem)).advisor)
    tasker = game.tasker()
    solved = game.solved()
    attacker = np.array([125.0, 150.0])  # north of the hall, 35 m short of home
    fixes = LatestFixes(scenario.map)
    lat, lon = scenario.map.to_geodetic(*attacker)
    fixes.take(Fix(agent="attacker", seq=1, t=1.0, lat=lat, lon=lon))
    x, y = np.meshgrid(*tasker.grid.axes(), indexing="ij")

    def answer(*centres):
        tasker.picture.possible = np.any([np.hypot(x - cx, y - cy) <= 6.0 for cx, cy in centres], axis=0)
        tasker.picture.updates += 1
        return advisor("attacker", fixes, 2.0)

    far = answer((30.0, 20.0))  # the south-west corner, behind the buildings
    assert far["worst_case"] and far["go"] and far["value"] <= 0
    assert solved.evaluate(attacker, (30.0, 20.0), "return").value <= 0
    both = answer((30.0, 20.0), (125.0, 170.0))  # and between the attacker and home
    assert both["worst_case"] and not both["go"] and both["value"] > 0
    assert both["value"] == pytest.approx(
        max(
            solved.evaluate(attacker, d, "return").value
            for d in np.argwhere(tasker.picture.possible) * np.asarray(tasker.grid.spacing) + np.asarray(tasker.grid.lo)
        ),
        abs=0.3,
    )


def test_a_capture_radius_the_grid_cannot_resolve_is_refused():
    from bearcat.scenarios.cast import _CtfGame

    coarse = parse_scenario(_text(**{"capture_radius = 7.5": "capture_radius = 5.0"}), source="s.toml")
    with pytest.raises(
        ScenarioError,
        match=r"capture_radius 5 m is less than a cell of the 35-point grid on map "
        r"campus-250x200 \(7.35 m\).*at least 51",
    ):
        _CtfGame(coarse)


@pytest.mark.parametrize("search", ["reachability", "nearest", "lawnmower"])
def test_two_uavs_search_together_and_never_the_same_place(search):
    second = """
[[uav]]
id = "q2"
team = "attacker"
start = [135.0, 12.0]
altitude = 25.0
camera_radius = 15.0
speed = 8.0
search = "reachability"
"""
    text = _text() + second
    text = text.replace('search = "reachability"', f'search = "{search}"')
    scenario = parse_scenario(text, source="two.toml")
    apart, flown = [], {"q1": 0.0, "q2": 0.0}

    def inspect(now, players):
        (tasker,) = players.tasking
        for name, uav in players.uavs.items():
            if uav.state is not None:
                flown[name] = max(flown[name], uav.state.alt)
        targets = tasker.picture.targets
        tracking = tasker.picture.sightings and now - tasker.picture.sightings[-1][0] <= TRACK_FOR + 1.0
        if targets.get("q1") and targets.get("q2") and not tracking:
            apart.append(math.dist(targets["q1"], targets["q2"]))

    simulate(scenario, seed=0, inspect=inspect)
    assert flown["q1"] > 19.0 and flown["q2"] > 24.0
    assert len(apart) > 10 and min(apart) >= 15.0  # each leaves the other's ground, 2 r_q wide, alone


def test_uavs_of_one_side_search_by_one_strategy():
    from bearcat.scenarios.cast import _CtfGame

    mixed = _text() + '[[uav]]\nid = "q2"\nteam = "attacker"\nstart = [135.0, 12.0]\nsearch = "nearest"\n'
    with pytest.raises(
        ScenarioError,
        match="the UAVs of a side search together, by one policy with one set of options; these mix nearest and "
        "reachability",
    ):
        _CtfGame(parse_scenario(mixed, source="mixed.toml")).tasker()
