"""The event log's lines: strict JSON any reader takes, read back as written."""

import json
import math

from bearcat.agents.ground_station.event_log import EventLog, read_events


def strict(line: str):
    def refuse(token):
        raise ValueError(f"{token} is not JSON")

    return json.loads(line, parse_constant=refuse)


def test_lines_are_strict_json_and_read_back_as_written(tmp_path):
    path = tmp_path / "events.jsonl"
    log = EventLog(path)
    log.note(1.5, "joined", peer="défenseur", pid=12, where=[1.0, 2.25], gap=None)
    log.note(2.0, "gap", seconds=math.inf, change=math.nan)
    log.close()
    lines = path.read_text(encoding="utf-8").splitlines()
    assert [strict(line) for line in lines] == read_events(path)
    assert read_events(path) == [
        {"event": "joined", "t": 1.5, "peer": "défenseur", "pid": 12, "where": [1.0, 2.25], "gap": None},
        {"event": "gap", "t": 2.0, "seconds": None, "change": None},  # JSON has no token for them
    ]


def test_a_log_written_with_nan_tokens_is_read_and_a_torn_last_line_ends_it(tmp_path):
    path = tmp_path / "events.jsonl"
    path.write_text('{"event":"a","t":1.0,"x":NaN}\n{"event":"b","t":2.0,"x":Infinity}\n{"event":"c","t":3')
    events = read_events(path)
    assert [e["event"] for e in events] == ["a", "b"]
    assert math.isnan(events[0]["x"]) and events[1]["x"] == math.inf
