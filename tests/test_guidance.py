"""The ground station's advisors answer from fixes as the solvers would from
the true positions: the open-loop path and safe set, the pursuit cell and
boundaries, and positions a fix put inside a building moved out first.
Regions go out as GeoJSON-ordered ``[lon, lat]`` rings and land on the
phone's screen where the solver put them."""

import msgspec
import numpy as np
import pytest
import shapely
from scipy import ndimage

from bearcat.agents.ground_station.guidance import CtfAdvisor, GuidanceService, PursuitAdvisor, ReachAvoidAdvisor
from bearcat.agents.ground_station.guidance.fixes import LatestFixes, Uncertainty
from bearcat.agents.ground_station.guidance.methods import WorstCase
from bearcat.agents.ground_station.tracker import Trackers
from bearcat.agents.guard import Guard
from bearcat.agents.human.phone import Phone
from bearcat.agents.options import NoOptions
from bearcat.bus import keys
from bearcat.bus.codec import decode, encode
from bearcat.bus.messages import Fix, Guidance
from bearcat.maps import load_map
from bearcat.maps.ctf import ctf_geometry
from bearcat.netem.models import CompassError, GpsError
from bearcat.solvers.ctf.queries import CtfQueries
from bearcat.solvers.ctf.sets import Rules, solve_ctf
from tests.support.answers import answering


def fixes_at(game_map, positions):
    fixes = LatestFixes(game_map)
    for k, (agent, (x, y)) in enumerate(positions.items()):
        lat, lon = game_map.to_geodetic(x, y)
        fixes.take(Fix(agent=agent, seq=1, t=1.0 + 0.01 * k, lat=lat, lon=lon))
    return fixes


def test_open_loop_guidance_follows_the_safe_path_of_the_readme_example():
    campus = load_map("campus-400")
    advisor = answering(
        ReachAvoidAdvisor(
            campus,
            attacker="a",
            defenders=["d1", "d2"],
            targets=["flag", "home"],
            speeds={"a": 5.0, "d1": 1.0, "d2": 0.5},
            capture_radius=2.0,
            spacing=2.0,
        )
    )
    fixes = fixes_at(campus, {"a": (370.0, 30.0), "d1": (120.0, 150.0), "d2": (330.0, 200.0)})
    shown = advisor("a", fixes, 2.0)
    assert shown["go"] is True and 0 <= shown["heading"] < 360
    path = np.array([campus.to_local(lat, lon) for lon, lat in shown["boundary"][0]])
    assert np.hypot(*(path[0] - (370.0, 30.0))) < 3.0
    assert campus.region("home").geometry.distance(__import__("shapely").Point(path[-1])) < 3.0
    # The heading points along the first stretch of the path.
    first = path[min(5, len(path) - 1)] - path[0]
    bearing = np.degrees(np.arctan2(first[0], first[1])) % 360
    assert min(abs(bearing - shown["heading"]), 360 - abs(bearing - shown["heading"])) < 30
    assert shown["region"] and shown["value"] > 0
    # Defenders fast enough to cut every path: no go, no heading.
    fast = answering(
        ReachAvoidAdvisor(
            campus,
            attacker="a",
            defenders=["d1", "d2"],
            targets=["flag", "home"],
            speeds={"a": 5.0, "d1": 10.0, "d2": 10.0},
            capture_radius=2.0,
            spacing=2.0,
        )
    )
    blocked = fast("a", fixes, 2.0)
    assert blocked["go"] is False and "heading" not in blocked


def test_a_fix_inside_a_building_is_answered_from_the_nearest_free_point():
    campus = load_map("campus-400")
    advisor = answering(
        ReachAvoidAdvisor(
            campus,
            attacker="a",
            defenders=["d1"],
            targets=["flag", "home"],
            speeds={"a": 5.0, "d1": 1.0},
            capture_radius=2.0,
            spacing=2.0,
        )
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


def sent_to(agent, game_map, fixes, fields) -> Guidance:
    """The guidance ``agent`` receives with ``fields``: encoded and decoded as on the bus."""
    message = Guidance(agent=agent, seq=1, t=2.0, reports=fixes.reports(2.0), **fields)
    return decode(encode(message), keys.guidance("g", agent))


def in_metres(game_map, ring) -> shapely.Polygon:
    """A ring of the wire read by the message's documented order, ``[lon, lat]``."""
    lon, lat = np.asarray(ring).T
    return shapely.Polygon(np.column_stack(game_map.to_local(lat, lon)))


def test_a_ctf_region_reads_as_lon_lat_rings_where_the_solver_puts_it():
    """Read as ``[lon, lat]``, the defender's winning region the attacker is
    sent has the solver's area and covers the nodes of the solver's mask, and
    no node well outside it; the phone's screen shows the same region."""
    ctf10 = load_map("ctf-10")
    queries = CtfQueries(solve_ctf(ctf_geometry(ctf10, 21), Rules(), "return", scheme="first"))
    advisor = answering(CtfAdvisor(ctf10, queries, attacker="a", defender="d", phase="return"))
    attacker = np.array([5.0, 3.0])
    fixes = fixes_at(ctf10, {"a": tuple(attacker), "d": (2.0, 6.0)})
    sent = sent_to("a", ctf10, fixes, advisor("a", fixes, 2.0))
    assert sent.region_of == "d" and sent.region
    received = shapely.union_all([in_metres(ctf10, ring) for ring in sent.region])

    values = queries.defender_region_values(attacker, "return")
    solver = shapely.union_all(
        [shapely.Polygon(p.exterior) for p in shapely.get_parts(queries.polygons(values, "defender"))]
    )
    assert received.area == pytest.approx(solver.area, rel=1e-3)
    assert received.symmetric_difference(solver).area < 1e-3 * solver.area

    x, y = np.meshgrid(*queries.geometry.grid.axes(), indexing="ij")
    inside = values > 0
    outside = ndimage.binary_erosion(~ndimage.binary_fill_holes(inside), border_value=1)
    assert inside.sum() > 10 and outside.sum() > 10
    phone = Phone("a", ctf10, gps=GpsError(), compass=CompassError(), rng=np.random.default_rng(0))
    phone.show(sent, 2.1)
    for mask, expected in ((inside, True), (outside, False)):
        nodes = np.column_stack([x[mask], y[mask]])
        assert all(received.buffer(1e-6).covers(shapely.Point(p)) == expected for p in nodes)
        assert all(phone.screen.in_region(p) == expected for p in nodes)


def test_a_pursuit_cell_reads_as_lon_lat_ring_of_the_area_sent_as_value():
    field = load_map("field-50")
    advisor = answering(PursuitAdvisor(field, evader="e", pursuers=["p1", "p2"]))
    fixes = fixes_at(field, {"e": (25.0, 25.0), "p1": (10.0, 10.0), "p2": (40.0, 12.0)})
    sent = sent_to("p1", field, fixes, advisor("p1", fixes, 2.0))
    (ring,) = sent.region
    cell = in_metres(field, ring)
    assert cell.is_valid and cell.area == pytest.approx(sent.value, rel=1e-4)
    assert cell.contains(shapely.Point(25.0, 25.0)) and not cell.contains(shapely.Point(10.0, 10.0))


# --- robust advice: the disks stale, noisy fixes allow ---


@pytest.fixture(scope="module")
def ctf10_game():
    ctf10 = load_map("ctf-10")
    return ctf10, CtfQueries(solve_ctf(ctf_geometry(ctf10, 21), Rules(), "return", scheme="first"))


def fix(game_map, agent, where, t, accuracy=None):
    lat, lon = game_map.to_geodetic(*where)
    return Fix(agent=agent, seq=1, t=t, lat=lat, lon=lon, accuracy=accuracy)


def test_each_report_carries_the_disk_its_agent_may_be_in():
    """Top speed x the fix's age, plus the fix's 95 % error circle (2.448
    sigma for a two-axis Gaussian); the phone shows the same radius."""
    field = load_map("field-50")
    uncertainty = Uncertainty({"a": 3.0, "b": 1.0})
    service = GuidanceService("g", field, ["a", "b"], rate=10.0, uncertainty=uncertainty)
    service.handle("bearcat/g/fix/a", fix(field, "a", (10.0, 10.0), 0.5, accuracy=2.0), 0.5)
    service.handle("bearcat/g/fix/b", fix(field, "b", (20.0, 10.0), 0.6), 0.6)
    (to_a, _) = service.tick(1.5)
    radius = {r.agent: r.radius for r in to_a.message.reports}
    assert radius["a"] == pytest.approx(3.0 * 1.0 + 2.448 * 2.0, abs=0.01)
    assert radius["b"] == pytest.approx(1.0 * 0.9, abs=0.01)
    assert Uncertainty({"a": 3.0}, confidence=0.0).radius("a", 1.0, 2.0) == 3.0
    phone = Phone("a", field, gps=GpsError(), compass=CompassError(), rng=np.random.default_rng(0))
    phone.show(decode(encode(to_a.message), keys.guidance("g", "a")), 1.6)
    assert phone.screen.reports["b"].radius == pytest.approx(0.9, abs=0.01)


def test_the_phone_shows_where_the_tracker_believes_each_agent_is_with_its_ellipse():
    """A tracked report lands on the screen at the tracker's belief (metres)
    with the belief's 95 % ellipse, bearing in radians; an untracked one has
    neither. A point the next guidance repeats is not converted again."""
    field = load_map("field-50")
    fixes = LatestFixes(field, Trackers(field, GpsError(), CompassError()))
    walk = np.array([0.8, 0.6])  # 2 m/s east-north-east
    for k in range(6):
        fixes.take(fix(field, "b", np.array([10.0, 10.0]) + 2.0 * k * walk, float(k), accuracy=1.0))
    fixes.take(fix(field, "a", (40.0, 40.0), 4.0))
    now = 6.5
    belief = fixes.beliefs(now)["b"]
    sent = Guidance(agent="a", seq=1, t=now, game="ctf", reports=fixes.reports(now))
    phone = Phone("a", field, gps=GpsError(), compass=CompassError(), rng=np.random.default_rng(0))
    phone.show(decode(encode(sent), keys.guidance("g", "a")), now)
    seen = phone.screen.reports["b"]
    assert seen.predicted is not None and seen.ellipse is not None
    assert np.hypot(*(seen.predicted - belief.position)) < 0.05  # the wire rounds to 1e-7 degrees
    assert np.dot(seen.predicted - seen.position, walk) > 2.0  # ahead of the fix, where the walk went on
    major, minor, bearing = belief.ellipse()
    assert seen.ellipse[:2] == pytest.approx((major, minor), abs=0.01)
    assert seen.ellipse[2] == pytest.approx(np.radians(bearing), abs=np.radians(0.06))
    assert seen.ellipse[0] >= seen.ellipse[1] > 0.0

    plain = [msgspec.structs.replace(r, predicted=None, ellipse=None) if r.agent == "a" else r for r in sent.reports]
    phone.show(msgspec.structs.replace(sent, seq=2, t=now + 0.1, reports=plain), now + 0.1)
    assert phone.screen.reports["b"].predicted is seen.predicted  # the same point, converted once
    assert phone.screen.reports["a"].predicted is None and phone.screen.reports["a"].ellipse is None
    later = fixes.reports(now + 1.0)
    phone.show(msgspec.structs.replace(sent, seq=3, t=now + 1.0, reports=later), now + 1.0)
    moved = phone.screen.reports["b"].predicted
    assert moved is not seen.predicted and np.dot(moved - seen.predicted, walk) > 1.0


def test_robust_advice_is_the_plain_one_for_fresh_exact_fixes_and_cautious_for_stale_ones(ctf10_game):
    ctf10, queries = ctf10_game
    advisor = CtfAdvisor(ctf10, queries, attacker="a", defender="d", phase="return")
    plain, robust = answering(advisor), answering(advisor, "worst_case")
    fixes = LatestFixes(ctf10)
    # A state the attacker barely wins: its value just below zero.
    states = [((x, y), (u, v)) for x in np.linspace(1, 9, 9) for y in np.linspace(1, 9, 9) for u, v in [(2.0, 6.0)]]
    values = [queries.evaluate(a, d, "return").value for a, d in states]
    a, d = states[int(np.argmin([abs(v + 0.2) for v in values]))]
    fixes.take(fix(ctf10, "a", a, 1.0))
    fixes.take(fix(ctf10, "d", d, 1.0))
    fresh = {agent: (plain(agent, fixes, 1.0), robust(agent, fixes, 1.0)) for agent in ("a", "d")}
    for shown, answer in fresh.values():
        assert answer["value"] == pytest.approx(shown["value"], abs=1e-6)
        assert answer["heading"] == pytest.approx(shown["heading"]) and not answer["uncertain"]
    assert fresh["a"][1]["go"] is True
    # Two seconds later the same fixes allow the defender to be where it wins:
    # no go, and the attacker is told the plain answer would differ.
    stale = robust("a", fixes, 3.0)
    assert stale["go"] is False and stale["uncertain"] and stale["value"] > fresh["a"][1]["value"]
    assert plain("a", fixes, 3.0)["go"] is True


def test_a_warmed_up_advisor_answers_every_fix_as_a_fresh_one_does(ctf10_game):
    """The warm-up keeps nothing that would stand in for a later answer: at
    the very positions it answered, with stale fixes that grow the robust
    disks, and after the phase changes."""
    ctf10, queries = ctf10_game
    common = dict(attacker="a", defender="d", phase="capture")
    advisors = CtfAdvisor(ctf10, queries, **common), CtfAdvisor(ctf10, queries, **common)
    a, d = (2.0, 2.0), (6.0, 6.0)
    methods = {agent: (WorstCase(NoOptions(), np.random.default_rng(0)), Guard(agent, "worst-case")) for agent in "ad"}
    GuidanceService("g", ctf10, ["a", "d"], advisor=advisors[0], methods=methods).warm_up({"a": a, "d": d})
    warmed, fresh = (answering(advisor, "worst_case") for advisor in advisors)
    fixes = LatestFixes(ctf10)
    fixes.take(fix(ctf10, "a", a, 1.0))
    fixes.take(fix(ctf10, "d", d, 1.0))
    for now in (1.0, 1.5, 3.0):
        for agent in ("a", "d"):
            assert warmed(agent, fixes, now) == fresh(agent, fixes, now)
    for advisor in advisors:
        advisor.phase = "return"
    assert warmed("a", fixes, 3.0) == fresh("a", fixes, 3.0)


def test_an_answer_after_either_player_moved_is_the_one_a_fresh_advisor_gives(ctf10_game):
    """The region an agent is sent depends on its own fix only, and is kept
    while the other player moves: every answer, region included, is still
    the one an advisor that never answered before gives."""
    ctf10, queries = ctf10_game
    advisor = answering(CtfAdvisor(ctf10, queries, attacker="a", defender="d", phase="return"))
    fixes = LatestFixes(ctf10)
    moves = [("a", (2.0, 2.0)), ("d", (6.0, 6.0)), ("d", (7.0, 5.0)), ("a", (3.0, 2.5)), ("d", (2.0, 6.0))]
    for t, (mover, where) in enumerate(moves, start=1):
        fixes.take(fix(ctf10, mover, where, float(t)))
        for agent in ("a", "d"):
            fresh = answering(CtfAdvisor(ctf10, queries, attacker="a", defender="d", phase="return"))
            assert advisor(agent, fixes, t + 0.5) == fresh(agent, fixes, t + 0.5)


def test_robust_open_loop_guidance_grows_each_defenders_capture_disk_by_its_uncertainty():
    """Fresh exact fixes give the plain answer; a defender fix grown stale
    (a 10 m/s defender whose fix is 11 s old may be 110 m away) cuts the safe
    path the plain answer still shows, and the attacker is told so."""
    campus = load_map("campus-400")
    speeds = {"a": 5.0, "d1": 1.0, "d2": 0.5}
    common = dict(attacker="a", defenders=["d1", "d2"], targets=["flag", "home"], capture_radius=2.0, spacing=2.0)
    plain = answering(ReachAvoidAdvisor(campus, speeds=speeds, **common))
    robust = answering(
        ReachAvoidAdvisor(campus, speeds=speeds, uncertainty=Uncertainty({"a": 5.0, "d1": 10.0, "d2": 10.0}), **common),
        "worst_case",
    )
    fixes = fixes_at(campus, {"a": (370.0, 30.0), "d1": (120.0, 150.0), "d2": (330.0, 200.0)})
    fresh = robust("a", fixes, 1.02)
    assert fresh["go"] is plain("a", fixes, 1.02)["go"] is True and not fresh["uncertain"]
    stale = robust("a", fixes, 12.0)
    assert plain("a", fixes, 12.0)["go"] is True
    assert stale["go"] is False and stale["uncertain"]


@pytest.mark.parametrize("name", ["pursuit-field", "open-loop"])
def test_each_games_guidance_warms_up_at_its_scenarios_starts_and_keeps_no_answer(name):
    """What a ground station peer runs before it says it is up: every
    player's start is where its advisor looks, and nothing is kept that a
    fix of the game would be answered from."""
    from bearcat.netem.profiles import load_profile
    from bearcat.scenarios.cast import build_cast
    from bearcat.scenarios.schema import load_scenario

    cast = build_cast(load_scenario(name), load_profile("ideal"), 0, people=[], ground=True)
    cast.warm_up()
    assert cast.guidance.advisor._last in ({}, None)
