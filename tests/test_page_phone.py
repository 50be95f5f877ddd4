"""The real phone's agent, without a browser: what its page reports becomes
fixes checked as any fix is, and what the ground station sends becomes the
screen the page draws."""

import math

import pytest

from bearcat.agents.human.page_phone import HELD, PagePhone
from bearcat.bus import keys
from bearcat.bus.messages import Fix, GameState, Guidance, Report
from bearcat.maps import load_map

GAME = "g"


@pytest.fixture
def phone():
    return PagePhone(GAME, "attacker", load_map("field-50"))


def _at(phone, x, y):
    lat, lon = phone.map.to_geodetic(x, y)
    return {"lat": lat, "lon": lon}


def test_a_reported_position_goes_out_as_a_fix_on_the_next_tick(phone):
    assert phone.report({**_at(phone, 10.0, 20.0), "accuracy": 9.79, "heading": 12.5, "age": 1500.0}, 100.0) is None
    (send,) = phone.tick(100.05)
    assert send.key == keys.fix(GAME, "attacker") and isinstance(send.message, Fix)
    fix = send.message
    assert fix.agent == "attacker" and fix.seq == 1 and fix.heading == 12.5
    assert fix.t == pytest.approx(98.5)  # measured 1.5 s before it reached the bridge, by the phone's own clock
    assert fix.accuracy == pytest.approx(4.0, abs=0.01)  # a 95 % radius of 9.79 m is 4 m per axis
    assert math.dist(phone.map.to_local(fix.lat, fix.lon), (10.0, 20.0)) < 1e-6
    assert phone.tick(100.15) == []


@pytest.mark.parametrize(
    ("report", "reason"),
    [
        ({"lat": 123.0, "lon": 0.0}, "lat"),
        ({"lat": 37.0, "lon": 0.0, "heading": 360.0}, "heading"),
        ({"lat": 37.0, "lon": 0.0, "accuracy": -1.0}, "accuracy"),
        ({"lat": 37.0, "lon": 0.0, "age": 3_600_000.0}, "age"),
        ({"lat": 37.0, "lon": 0.0, "altitude": 3.0}, "altitude"),
        ({"lat": "north", "lon": 0.0}, "lat"),
        ({"lon": 0.0}, "lat"),
        (["not", "a", "map"], ""),
    ],
)
def test_a_bad_report_is_dropped_counted_and_never_sent(phone, report, reason):
    why = phone.report(report, 100.0)
    assert why is not None and why.startswith("fix dropped") and reason in why
    assert sum(phone.drops.values()) == 1 and phone.tick(100.1) == [] and phone.seq == 0


def test_a_page_that_floods_loses_its_oldest_reports_not_the_bus(phone):
    for k in range(3 * HELD):
        phone.report({**_at(phone, 10.0, 10.0 + 0.1 * k)}, 100.0 + 0.001 * k)
    sent = phone.tick(101.0)
    assert len(sent) == HELD and [s.message.seq for s in sent] == list(range(2 * HELD + 1, 3 * HELD + 1))


def test_the_view_is_the_screen_at_now(phone):
    phone.report({**_at(phone, 10.0, 20.0), "accuracy": 9.79, "age": 0.0}, 100.0)
    lat, lon = phone.map.to_geodetic(30.0, 40.0)
    guidance = Guidance(
        agent="attacker",
        seq=1,
        t=100.2,
        game="ctf",
        heading=90.0,
        go=False,
        reports=[Report(agent="defender", t=99.0, lat=lat, lon=lon, radius=5.0)],
    )
    phone.handle(keys.guidance(GAME, "attacker"), guidance, 100.3)
    phone.handle(keys.state(GAME), GameState(seq=4, t=100.3, phase="running"), 100.3)
    phone.handle(keys.state(GAME), GameState(seq=3, t=100.1, phase="waiting"), 100.35)  # older: ignored
    view = phone.view(101.0)
    assert view["phase"] == "running" and view["go"] is False and view["heading"] == pytest.approx(90.0)
    assert view["guidance_age"] == pytest.approx(0.7)
    (defender,) = view["reports"]
    assert defender["agent"] == "defender" and defender["age"] == pytest.approx(2.0) and defender["radius"] == 5.0
    assert math.dist((defender["x"], defender["y"]), (30.0, 40.0)) < 1e-6
    assert view["fix"]["accuracy"] == pytest.approx(9.79) and view["fix"]["age"] == pytest.approx(1.0)
    shown = phone.map_view()
    assert shown["bounds"] == [0.0, 0.0, 50.0, 50.0] and set(shown["regions"]) == {"home", "flag"}


def test_the_view_carries_each_reports_prediction_and_ellipse_in_map_metres(phone):
    """A calibrated report's prediction is drawn in the frame the page draws
    the fix in, and its ellipse keeps the wire's axes and bearing; a report
    without one is drawn as before, fix and disk."""
    fix_lat, fix_lon = phone.map.to_geodetic(30.0, 40.0)
    lat, lon = phone.map.to_geodetic(24.0, 31.5)
    reports = [
        Report(
            agent="defender",
            t=99.0,
            lat=fix_lat,
            lon=fix_lon,
            radius=5.0,
            predicted=(lon, lat),
            ellipse=(6.5, 2.25, 152.5),
        ),
        Report(agent="attacker", t=99.5, lat=lat, lon=lon, radius=3.0),
    ]
    phone.handle(
        keys.guidance(GAME, "attacker"), Guidance(agent="attacker", seq=1, t=100.0, game="ctf", reports=reports), 100.0
    )
    attacker, defender = phone.view(100.5)["reports"]
    assert math.dist((defender["x"], defender["y"]), (30.0, 40.0)) < 1e-6
    sent_lon, sent_lat = reports[0].predicted
    assert math.dist(defender["predicted"], phone.map.to_local(sent_lat, sent_lon)) < 1e-6
    assert math.dist(defender["predicted"], (24.0, 31.5)) < 1e-6
    assert defender["ellipse"] == pytest.approx([6.5, 2.25, 152.5])
    assert attacker["predicted"] is None and attacker["ellipse"] is None and attacker["radius"] == 3.0
