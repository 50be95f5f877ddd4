"""The codec's size cap agrees with the messages: the largest one the schema
admits fits under it, and so does the largest guidance a real game sends
(the search game on campus-250x200), both encoded and decoded unchanged."""

import msgspec

from bearcat.agents.ground_station.recorder import read_events
from bearcat.bus import keys
from bearcat.bus.codec import MAX_PAYLOAD, decode, encode
from bearcat.bus.messages import Guidance, Report
from bearcat.scenarios.schema import load_scenario
from bearcat.scenarios.simulate import simulate

NAME = "n" * 64  # the longest name a key allows


def test_the_largest_message_the_schema_admits_fits_under_the_cap():
    # Every list at its longest, every float and integer at its widest encoding, every text in 4-byte characters.
    lines = [[(-89.123456789, -179.123456789)] * 4096] * 64
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
