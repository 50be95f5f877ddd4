"""The ground station's advisors answer from fixes as the solvers would from
the true positions: the open-loop path and safe set, the pursuit cell and
boundaries, and positions a fix put inside a building moved out first."""

import numpy as np
import pytest

from bearcat.agents.ground_station.guidance import GuidanceService, ReachAvoidAdvisor, _Fixes
from bearcat.bus.messages import Fix
from bearcat.maps import load_map


def fixes_at(game_map, positions):
    fixes = _Fixes(game_map)
    for k, (agent, (x, y)) in enumerate(positions.items()):
        lat, lon = game_map.to_geodetic(x, y)
        fixes.take(Fix(agent=agent, seq=1, t=1.0 + 0.01 * k, lat=lat, lon=lon))
    return fixes


def test_open_loop_guidance_follows_the_safe_path_of_the_readme_example():
    campus = load_map("campus-400")
    advisor = ReachAvoidAdvisor(
        campus,
        attacker="a",
        defenders=["d1", "d2"],
        targets=["flag", "home"],
        speeds={"a": 5.0, "d1": 1.0, "d2": 0.5},
        capture_radius=2.0,
        spacing=2.0,
    )
    fixes = fixes_at(campus, {"a": (370.0, 30.0), "d1": (120.0, 150.0), "d2": (330.0, 200.0)})
    shown = advisor("a", fixes, 2.0)
    assert shown["go"] is True and 0 <= shown["heading"] < 360
    path = np.array([campus.to_local(lat, lon) for lat, lon in shown["boundary"][0]])
    assert np.hypot(*(path[0] - (370.0, 30.0))) < 3.0
    assert campus.region("home").geometry.distance(__import__("shapely").Point(path[-1])) < 3.0
    # The heading points along the first stretch of the path.
    first = path[min(5, len(path) - 1)] - path[0]
    bearing = np.degrees(np.arctan2(first[0], first[1])) % 360
    assert min(abs(bearing - shown["heading"]), 360 - abs(bearing - shown["heading"])) < 30
    assert shown["region"] and shown["value"] > 0
    # Defenders fast enough to cut every path: no go, no heading.
    fast = ReachAvoidAdvisor(
        campus,
        attacker="a",
        defenders=["d1", "d2"],
        targets=["flag", "home"],
        speeds={"a": 5.0, "d1": 10.0, "d2": 10.0},
        capture_radius=2.0,
        spacing=2.0,
    )
    blocked = fast("a", fixes, 2.0)
    assert blocked["go"] is False and "heading" not in blocked


def test_a_fix_inside_a_building_is_answered_from_the_nearest_free_point():
    campus = load_map("campus-400")
    advisor = ReachAvoidAdvisor(
        campus,
        attacker="a",
        defenders=["d1"],
        targets=["flag", "home"],
        speeds={"a": 5.0, "d1": 1.0},
        capture_radius=2.0,
        spacing=2.0,
    )
    inside = np.asarray(campus.obstacles[0].representative_point().coords[0])
    shown = advisor("a", fixes_at(campus, {"a": (370.0, 30.0), "d1": tuple(inside)}), 2.0)
    assert "note" not in shown and shown["go"] in (True, False)


def test_guidance_goes_out_on_each_new_fix_and_at_the_rate_otherwise():
    field = load_map("field-50")
    service = GuidanceService("g", field, ["a", "b"], rate=10.0)
    lat, lon = field.to_geodetic(10.0, 10.0)
    sends = service.handle("bearcat/g/fix/a", Fix(agent="a", seq=1, t=0.5, lat=lat, lon=lon), 0.5)
    assert [s.message.agent for s in sends] == ["a"]
    assert service.handle("bearcat/g/fix/a", Fix(agent="a", seq=0, t=0.4, lat=lat, lon=lon), 0.52) == []  # older
    assert [s.message.agent for s in service.tick(0.55)] == ["b"]  # a was answered 0.05 s ago
    assert [s.message.agent for s in service.tick(0.6)] == ["a"]
    assert all(m.message.reports[0].t == 0.5 for m in service.tick(0.7))


@pytest.mark.parametrize("agent", ["a", "nobody"])
def test_positions_only_guidance_for_an_unaided_agent(agent):
    field = load_map("field-50")
    service = GuidanceService("g", field, [agent], rate=10.0)
    (send,) = service.tick(0.1)
    assert send.message.game == "none" and send.message.heading is None and send.message.region == []
