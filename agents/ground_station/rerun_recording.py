"""A run's Rerun recording, made from its event log: what the ground station
saw and what each phone showed, on one time line.

- ``map``: the area, buildings and game regions (static);
- ``ground/truth/AGENT``: where each agent really was (simulation only);
- ``ground/fix/AGENT``: each agent as its fixes reported it, beside the truth;
- ``ground/uav/UAV``: each UAV's search target and its detections;
- ``phone/AGENT/...``: that phone's screen as of the guidance it had
  received: the opponent's winning region, the heading ring's arrow, the
  agents as last reported, where an unseen opponent may be (P_D) and an
  alert when a UAV saw this agent;
- ``game``: the referee's states as a text log, and the solver's value
  shown to each phone as a plot.

Built after the run from ``events.jsonl``, so the recording never slows a
game down, and any event log (simulated or live) can be turned into one.
"""

from __future__ import annotations

import importlib.util
import logging
from pathlib import Path

import numpy as np

from bearcat.agents.ground_station.event_log import read_events
from bearcat.maps import Map

log = logging.getLogger(__name__)

COLOURS = [(31, 119, 180), (214, 39, 40), (44, 160, 44), (255, 127, 14), (148, 103, 189), (140, 86, 75)]


def finish_run(directory: str | Path, game_map: Map, name: str) -> Path | None:
    """Write a run directory's ``map.geojson`` and, from its ``events.jsonl``,
    its ``recording.rrd``; the recording's path (None without rerun-sdk)."""
    from bearcat.maps import write_geojson

    directory = Path(directory)
    write_geojson(game_map, directory / "map.geojson", units="metres")
    if importlib.util.find_spec("rerun") is None:
        log.warning("rerun-sdk is not installed: %s has an event log but no recording", directory)
        return None
    return write_recording(directory / "events.jsonl", game_map, directory / "recording.rrd", name=name)


def write_recording(events_path: str | Path, game_map: Map, rrd_path: str | Path, *, name: str = "bearcat") -> Path:
    import rerun as rr

    events = read_events(events_path)
    rec = rr.RecordingStream(f"bearcat-{name}", recording_id=str(Path(events_path).resolve()))
    start = min((e["t"] for e in events if "t" in e), default=0.0)
    to_local = _converter(game_map)
    colour: dict[str, tuple] = {}

    def colour_of(agent: str):
        return colour.setdefault(agent, COLOURS[len(colour) % len(COLOURS)])

    _log_map(rec, rr, game_map)
    sent = {}
    for e in events:
        if e["event"] == "sent":
            m = e["message"]
            sent[(e["key"], m.get("seq"))] = m
    for e in events:
        rec.set_time("game_time", duration=max(e["t"] - start, 0.0))
        kind = e["event"]
        if kind == "sent":
            m = e["message"]
            if m["type"] == "truth":
                rec.log(
                    f"ground/truth/{m['agent']}",
                    rr.Points2D(
                        [to_local(m["lat"], m["lon"])], radii=0.6, colors=[colour_of(m["agent"])], labels=[m["agent"]]
                    ),
                )
            elif m["type"] == "state":
                rec.log(
                    "game/state", rr.TextLog(f"{m['phase']}: {m.get('winner') or ''} {m.get('reason', '')}".strip())
                )
            elif m["type"] == "fix" and e["sender"] != "launcher":
                _log_fix(rec, rr, m, to_local, colour_of)
            elif m["type"] == "uav-task":
                rec.log(
                    f"ground/uav/{m['uav']}/target",
                    rr.Points2D(
                        [to_local(m["lat"], m["lon"])],
                        radii=1.5,
                        colors=[colour_of(m["uav"])],
                        labels=[f"{m['uav']} {m['kind']}"],
                    ),
                )
            elif m["type"] == "detection":
                rec.log(
                    f"ground/uav/{m['uav']}/detection",
                    rr.Points2D(
                        [to_local(m["lat"], m["lon"])],
                        radii=2.0,
                        colors=[(255, 200, 0)],
                        labels=[f"{m['agent']} seen by {m['uav']}"],
                    ),
                )
        elif kind == "received":
            m = sent.get((e["key"], e.get("seq")))
            if m is None:
                continue
            if m["type"] == "guidance":
                _log_screen(rec, rr, m, to_local, colour_of)
            elif m["type"] == "fix" and e["receiver"] == "gs":
                _log_fix(rec, rr, m, to_local, colour_of)
    rrd_path = Path(rrd_path)
    rec.save(rrd_path)
    return rrd_path


def _converter(game_map: Map):
    def to_local(lat, lon):
        x, y = game_map.to_local(lat, lon)
        return (float(x), float(y))

    return to_local


def _log_map(rec, rr, game_map: Map) -> None:
    rec.log(
        "map/area", rr.LineStrips2D([np.asarray(game_map.area.exterior.coords)], colors=[(90, 90, 90)]), static=True
    )
    if game_map.obstacles:
        rings = [np.asarray(o.exterior.coords) for o in game_map.obstacles]
        rec.log("map/buildings", rr.LineStrips2D(rings, colors=[(60, 60, 60)], radii=0.3), static=True)
    for name, region in game_map.regions.items():
        parts = getattr(region.geometry, "geoms", [region.geometry])
        rings = [np.asarray(p.exterior.coords) for p in parts]
        rec.log(f"map/regions/{name}", rr.LineStrips2D(rings, colors=[(0, 150, 0)], labels=[name]), static=True)


def _log_fix(rec, rr, m, to_local, colour_of) -> None:
    rec.log(
        f"ground/fix/{m['agent']}",
        rr.Points2D([to_local(m["lat"], m["lon"])], radii=0.4, colors=[colour_of(m["agent"])]),
    )


def _log_screen(rec, rr, m, to_local, colour_of) -> None:
    agent = m["agent"]
    base = f"phone/{agent}"
    rings = [np.array([to_local(lat, lon) for lat, lon in ring]) for ring in m.get("region", []) if ring]
    rec.log(f"{base}/region", rr.LineStrips2D(rings, colors=[(230, 60, 160)]) if rings else rr.Clear(recursive=False))
    possible = [np.array([to_local(lat, lon) for lat, lon in ring]) for ring in m.get("possible", []) if ring]
    if possible or m.get("game") == "search":
        rec.log(
            f"{base}/possible",
            rr.LineStrips2D(possible, colors=[(255, 140, 0)]) if possible else rr.Clear(recursive=False),
        )
    if m.get("seen_by"):
        rec.log(f"{base}/alert", rr.TextLog(f"{agent} seen by {', '.join(m['seen_by'])}"))
    reports = m.get("reports", [])
    if reports:
        points = [to_local(r["lat"], r["lon"]) for r in reports]
        rec.log(
            f"{base}/agents",
            rr.Points2D(
                points, radii=0.5, labels=[r["agent"] for r in reports], colors=[colour_of(r["agent"]) for r in reports]
            ),
        )
        me = next((p for p, r in zip(points, reports) if r["agent"] == agent), None)
        if me is not None and m.get("heading") is not None:
            b = np.radians(m["heading"])
            rec.log(
                f"{base}/heading",
                rr.Arrows2D(origins=[me], vectors=[(4 * np.sin(b), 4 * np.cos(b))], colors=[colour_of(agent)]),
            )
    if m.get("value") is not None:
        rec.log(f"game/value/{agent}", rr.Scalars(m["value"]))
