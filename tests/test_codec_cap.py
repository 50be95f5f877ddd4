"""The codec's size cap agrees with the messages: the largest one the schema
admits fits under it, and so does the largest guidance a real game sends
(the search game on campus-250x200), both encoded and decoded unchanged."""

import msgspec
import numpy as np
import pytest

from bearcat.agents.ground_station.event_log import read_events
from bearcat.agents.ground_station.guidance.outlines import on_the_wire
from bearcat.bus import keys
from bearcat.bus.codec import MAX_PAYLOAD, Refused, decode, encode
from bearcat.bus.messages import OUTLINE_LINES, OUTLINE_POINTS, Guidance, Report
from bearcat.maps import load_map
from bearcat.runtime.simulate import simulate
from bearcat.scenarios.schema import load_scenario

NAME = "n" * 64  # the longest name a key allows


def test_the_largest_message_the_schema_admits_fits_under_the_cap():
    # Every list at its longest, every float and integer at its widest encoding, every text in 4-byte characters.
    lines = [[(-179.123456789, -89.123456789)] * (OUTLINE_POINTS // OUTLINE_LINES)] * OUTLINE_LINES
    largest = Guidance(
        agent=NAME,
        seq=2**63 - 1,
        t=1e12,
        game="reach-avoid",
        heading=359.9,
        region=lines,
        region_of=NAME,
        go=True,
        value=-1.5e308,
        boundary=lines,
        reports=[Report(NAME, 1e12, -89.1, -179.1)] * 64,
        possible=lines,
        worst_case=True,
        seen_by=[NAME] * 64,
        note="\U0001f600" * 200,
    )
    payload = encode(largest)
    assert 0.8 * MAX_PAYLOAD < len(payload) <= MAX_PAYLOAD
    assert decode(payload, keys.guidance("g", NAME)) == largest


def test_the_largest_guidance_of_the_search_game_round_trips(tmp_path):
    scenario = load_scenario("search")
    assert scenario.map.name == "campus-250x200"
    events = tmp_path / "events.jsonl"
    simulate(scenario, seed=0, events=events)
    sent = [
        msgspec.convert(e["message"], Guidance)
        for e in read_events(events)
        if e["event"] == "sent" and e["message"]["type"] == "guidance"
    ]
    largest = max(sent, key=lambda m: len(encode(m)))
    assert largest.game == "search" and largest.region and largest.possible
    payload = encode(largest)
    assert len(payload) <= MAX_PAYLOAD
    assert decode(payload, keys.guidance(scenario.name, largest.agent)) == largest


def test_an_outline_of_more_points_than_the_schema_admits_is_refused():
    ring = [(-122.0, 37.0)] * (OUTLINE_POINTS // 2 + 1)
    with pytest.raises(ValueError, match="region has 4098 points in all"):
        Guidance(agent="a", seq=0, t=0.0, game="ctf", region=[ring, ring])
    payload = msgspec.msgpack.encode(
        {"type": "guidance", "v": 1, "agent": "a", "seq": 0, "t": 0.0, "game": "ctf", "region": [ring, ring]}
    )
    with pytest.raises(Refused, match="region has 4098 points in all"):
        decode(payload, keys.guidance("g", "a"))


def test_a_finely_traced_region_is_simplified_to_fit_and_keeps_its_shape():
    """A circle of 50,000 points (a fine contour of a large region) goes out
    within the point budget, still closed and within a few centimetres of the circle."""
    game_map = load_map("campus-400")
    angles = np.linspace(0.0, 2.0 * np.pi, 50_000)
    circle = np.column_stack([200.0 + 150.0 * np.cos(angles), 200.0 + 150.0 * np.sin(angles)])
    (ring,) = on_the_wire(game_map, [circle])
    assert 16 < len(ring) <= OUTLINE_POINTS and ring[0] == ring[-1]
    lon, lat = np.array(ring).T
    x, y = game_map.to_local(lat, lon)
    radius = np.hypot(x - 200.0, y - 200.0)
    assert np.abs(radius - 150.0).max() < 0.05
    Guidance(agent="a", seq=0, t=0.0, game="ctf", region=[ring])  # the schema takes it
