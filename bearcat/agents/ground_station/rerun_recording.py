"""A run's Rerun recording, made from its event log: what the ground station
saw and what each phone showed, on one time line.

- ``map``: the area, buildings and game regions (static);
- ``ground/truth/AGENT``: where each agent really was (simulation only);
- ``ground/fix/AGENT``: each agent as its fixes reported it, beside the truth;
- ``ground/uncertainty/AGENT``: the disk the guidance put round each
  agent's last report (where it may be by then), over the truth;
- ``ground/prediction/AGENT``: with calibrated guidance, the 95 % ellipse
  of where the tracker believed each agent was, over the truth;
- ``ground/uav/UAV``: each UAV's search target and its detections;
- ``phone/AGENT/...``: that phone's screen as of the guidance it had
  received: the opponent's winning region, the heading ring's arrow, the
  agents as last reported with their disks and the reports' ages (and,
  with calibrated guidance, the trackers' ellipses), where an
  unseen opponent may be (P_D), an alert when a UAV saw this agent, a
  note when the advice is uncertain (the robust and the plain answers
  differ), and each new line the guidance method puts on the screen
  (``note``: "no advice" where it failed, or what a method of one's own says);
- ``game``: the referee's states as a text log, and the solver's value
  shown to each phone as a plot.

Every map is drawn north up and east right, the agents as the thesis draws
them (the attacker, or evader, a blue circle; the defender, or pursuer, a red
triangle; a UAV a square in its team's colour), and the recording carries a
layout: the ground station's picture on the left, each phone's screen on the
right above the referee's log and the solver's value.

Built after the run from ``events.jsonl``, so the recording never slows a
game down, and any event log (simulated or live) can be turned into one.
"""

from __future__ import annotations

import importlib.util
import logging
from collections import OrderedDict
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from bearcat.agents.ground_station.event_log import iter_events
from bearcat.bus.keys import GROUND
from bearcat.maps import Map

log = logging.getLogger(__name__)

BLUE = (40, 100, 255)
RED = (230, 30, 30)
# The thesis's figures: the attacker (or evader) a blue circle, the defender (or pursuer) a red triangle.
TEAM_MARKERS = {
    "attacker": ("circle", BLUE),
    "evader": ("circle", BLUE),
    "defender": ("triangle", RED),
    "pursuer": ("triangle", RED),
}
# Members of no known team, in order of appearance.
OTHER_COLOURS = [(44, 160, 44), (255, 127, 14), (148, 103, 189), (140, 86, 75), (23, 190, 207)]
AREA = (128, 128, 128)
BUILDINGS = (70, 70, 70)
REGIONS = (0, 170, 0)
# The entity trees drawn on the map; each is mirrored north-south (see _north_up).
FIELD_ROOTS = ("map", "ground", "phone")
PENDING = 4096  # sent guidance and fixes the drawing remembers while they are in flight


def finish_run(directory: str | Path, scenario) -> Path | None:
    """Write a run directory's ``map.geojson`` and, from its ``events.jsonl``,
    its ``recording.rrd``, with each agent and UAV of ``scenario`` drawn as
    its team; the recording's path (None without rerun-sdk)."""
    from bearcat.maps import write_geojson

    directory = Path(directory)
    write_geojson(scenario.map, directory / "map.geojson", units="metres")
    if importlib.util.find_spec("rerun") is None:
        log.warning("rerun-sdk is not installed: %s has an event log but no recording", directory)
        return None
    teams = {member.id: member.team for member in (*scenario.agents, *scenario.uavs)}
    return write_recording(
        directory / "events.jsonl", scenario.map, directory / "recording.rrd", name=scenario.name, teams=teams
    )


def write_recording(
    events_path: str | Path,
    game_map: Map,
    rrd_path: str | Path,
    *,
    name: str = "bearcat",
    teams: Mapping[str, str] | None = None,
) -> Path:
    """Turn an event log into a Rerun recording; ``teams`` (agent or UAV id ->
    team) picks each one's marker, and without it every agent is a circle of
    its own colour."""
    import rerun as rr
    import rerun.blueprint as rrb

    rec = rr.RecordingStream(f"bearcat-{name}", recording_id=str(Path(events_path).resolve()))
    # A first pass for what the drawing needs up front, a second to draw: the
    # log is read line by line twice, never held whole, however long the run.
    start, flying, valued = None, set(), set()
    for e in iter_events(events_path):
        if "t" in e:
            start = e["t"] if start is None else min(start, e["t"])
        m = e.get("message") if e["event"] == "sent" else None
        if m is not None and m["type"] in ("truth", "fix") and m.get("alt") is not None:
            flying.add(m["agent"])  # only UAVs report an altitude
        elif m is not None and m["type"] == "guidance" and m.get("value") is not None:
            valued.add(m["agent"])
    start = start or 0.0
    to_local = _converter(game_map)
    markers = _Markers(rr, game_map, teams or {}, flying)
    phones: list[str] = []
    notes: dict[str, str] = {}  # agent -> the note its screen shows

    for root in FIELD_ROOTS:
        rec.log(root, _north_up(rr), static=True)
    _log_map(rec, rr, game_map)
    for agent in sorted(valued):
        rec.log(f"game/value/{agent}", rr.SeriesLines(colors=[markers.colour(agent)], names=[agent]), static=True)
    pending: OrderedDict = OrderedDict()  # guidance and fixes sent, until they arrive (the latest few thousand)
    for e in iter_events(events_path):
        rec.set_time("game_time", duration=max(e["t"] - start, 0.0))
        kind = e["event"]
        if kind == "sent":
            m = e["message"]
            if m["type"] in ("guidance", "fix"):
                pending[(e["key"], m.get("seq"))] = m
                if len(pending) > PENDING:
                    pending.popitem(last=False)
            if m["type"] == "truth":
                drawn = markers.draw([(m["agent"], to_local(m["lat"], m["lon"]))])
                rec.log(f"ground/truth/{m['agent']}", drawn[markers.shape(m["agent"])])
            elif m["type"] == "state":
                rec.log("game/state", rr.TextLog(_state_line(m)))
            elif m["type"] == "fix" and e["sender"] != "launcher":
                _log_fix(rec, rr, m, to_local, markers)
            elif m["type"] == "uav-task":
                rec.log(
                    f"ground/uav/{m['uav']}/target",
                    rr.Points2D(
                        [to_local(m["lat"], m["lon"])],
                        radii=1.5,
                        colors=[markers.colour(m["uav"])],
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
            m = pending.get((e["key"], e.get("seq")))
            if m is None:
                continue
            if m["type"] == "guidance":
                if m["agent"] not in phones:
                    phones.append(m["agent"])
                _log_screen(rec, rr, m, to_local, markers)
                if m.get("note", "") != notes.get(m["agent"], ""):
                    notes[m["agent"]] = m.get("note", "")
                    said = notes[m["agent"]] or "(no note)"
                    rec.log(f"phone/{m['agent']}/note", rr.TextLog(f"{m['agent']}'s phone says: {said}"))
            elif m["type"] == "fix" and e["receiver"] == GROUND:
                _log_fix(rec, rr, m, to_local, markers)
    rrd_path = Path(rrd_path)
    rec.save(rrd_path, default_blueprint=_layout(rrb, game_map, phones))
    return rrd_path


def _converter(game_map: Map):
    def to_local(lat, lon):
        x, y = game_map.to_local(lat, lon)
        return (float(x), float(y))

    return to_local


def _north_up(rr):
    """Rerun draws 2-D views with y down, as for images; mirroring y puts north (+y) at the top."""
    return rr.Transform3D(scale=[1.0, -1.0, 1.0])


def _layout(rrb, game_map: Map, phones: list[str]):
    """The ground station's picture on the left; on the right each phone's
    screen above the referee's states with the alerts, and the solver's
    value; every map filling its view."""
    west, south, east, north = game_map.bounds
    margin = 0.03 * max(east - west, north - south)
    # y is mirrored (_north_up): the view runs from -north to -south.
    bounds = rrb.VisualBounds2D(x_range=[west - margin, east + margin], y_range=[-north - margin, -south + margin])

    def field(name: str, drawn: str):
        return rrb.Spatial2DView(name=name, origin="/", contents=["/map/**", drawn], visual_bounds=bounds)

    texts = rrb.TextLogView(
        name="referee and alerts",
        origin="/",
        columns=rrb.TextLogColumns(
            timeline_columns=[rrb.encodings.TimelineColumn("game_time")],
            text_log_columns=[
                rrb.encodings.TextLogColumn("body"),
                rrb.encodings.TextLogColumn("entitypath", visible=False),
                rrb.encodings.TextLogColumn("loglevel", visible=False),
            ],
        ),
    )
    logs = rrb.Horizontal(texts, rrb.TimeSeriesView(name="value", origin="/game/value"))
    screens = [field(f"{agent}'s phone", f"/phone/{agent}/**") for agent in phones]
    right = rrb.Vertical(rrb.Grid(*screens), logs, row_shares=[2, 1]) if screens else logs
    return rrb.Blueprint(
        rrb.Horizontal(field("ground station", "/ground/**"), right),
        rrb.TimePanel(timeline="game_time"),
    )


class _Markers:
    """How each agent is drawn: its team's shape and colour (a UAV a square),
    at a size that reads on this map."""

    def __init__(self, rr, game_map: Map, teams: Mapping[str, str], flying: set[str]) -> None:
        self.rr = rr
        self.teams = teams
        self.flying = flying
        west, south, east, north = game_map.bounds
        self.size = max(1.0, 0.015 * max(east - west, north - south))  # m, a circle's radius
        self._others: dict[str, tuple] = {}

    def colour(self, agent: str) -> tuple:
        return self._style(agent)[1]

    def shape(self, agent: str) -> str:
        return "square" if agent in self.flying else self._style(agent)[0]

    def draw(self, placed: list[tuple[str, tuple[float, float]]]) -> dict:
        """The archetypes that draw ``placed`` (agent, (x, y)) pairs, by
        shape: circle, triangle and square, each a batch (empty ones clear)."""
        rr, size = self.rr, self.size
        by_shape: dict[str, list] = {"circle": [], "triangle": [], "square": []}
        for agent, point in placed:
            by_shape[self.shape(agent)].append((agent, point, self.colour(agent)))

        def fields(shape: str):
            chosen = by_shape[shape]
            return [p for _, p, _ in chosen], [c for _, _, c in chosen], [a for a, _, _ in chosen]

        def outlines(shape: str, corners_at: list[float], reach: float, stroke: float):
            """Closed outlines around each point, corners at these bearings (degrees) ``reach`` out; line
            strips, since Rerun places a box's label as if north were down."""
            points, colours, labels = fields(shape)
            corners = [(np.sin(a), np.cos(a)) for a in np.radians([*corners_at, corners_at[0]])]
            rings = [[(x + reach * dx, y + reach * dy) for dx, dy in corners] for x, y in points]
            return rr.LineStrips2D(rings, radii=stroke, colors=colours, labels=labels)

        points, colours, labels = fields("circle")
        circles = rr.Points2D(points, radii=size, colors=colours, labels=labels)
        # A triangle pointing north, its stroke as wide as its inner radius, so it reads as filled.
        triangles = outlines("triangle", [0.0, 120.0, 240.0], 0.7 * size, 0.35 * size)
        # A UAV, seen from above: a square frame.
        squares = outlines("square", [45.0, 135.0, 225.0, 315.0], np.sqrt(2.0) * size, 0.15 * size)
        return {"circle": circles, "triangle": triangles, "square": squares}

    def _style(self, agent: str) -> tuple[str, tuple]:
        marker = TEAM_MARKERS.get(self.teams.get(agent, ""))
        if marker is not None:
            return marker
        return "circle", self._others.setdefault(agent, OTHER_COLOURS[len(self._others) % len(OTHER_COLOURS)])


def _log_map(rec, rr, game_map: Map) -> None:
    rec.log("map/area", rr.LineStrips2D([np.asarray(game_map.area.exterior.coords)], colors=[AREA]), static=True)
    if game_map.obstacles:
        rings = [np.asarray(o.exterior.coords) for o in game_map.obstacles]
        rec.log("map/buildings", rr.LineStrips2D(rings, colors=[BUILDINGS], radii=0.3), static=True)
    for name, region in game_map.regions.items():
        parts = getattr(region.geometry, "geoms", [region.geometry])
        rings = [np.asarray(p.exterior.coords) for p in parts]
        rec.log(f"map/regions/{name}", rr.LineStrips2D(rings, colors=[REGIONS], labels=[name]), static=True)


def _paler(colour: tuple) -> tuple:
    """A shade halfway to white: what was reported of an agent, beside the marker of where it was."""
    return tuple(int(c + (255 - c) * 0.5) for c in colour)


def _log_fix(rec, rr, m, to_local, markers: _Markers) -> None:
    """A fix as a small dot in a paler shade of its agent's colour, beside the truth's marker."""
    paler = _paler(markers.colour(m["agent"]))
    rec.log(
        f"ground/fix/{m['agent']}",
        rr.Points2D([to_local(m["lat"], m["lon"])], radii=0.35 * markers.size, colors=[paler]),
    )


def _log_screen(rec, rr, m, to_local, markers: _Markers) -> None:
    agent = m["agent"]
    base = f"phone/{agent}"
    rings = [np.array([to_local(lat, lon) for lon, lat in ring]) for ring in m.get("region", []) if ring]
    rec.log(f"{base}/region", rr.LineStrips2D(rings, colors=[(230, 60, 160)]) if rings else rr.Clear(recursive=False))
    possible = [np.array([to_local(lat, lon) for lon, lat in ring]) for ring in m.get("possible", []) if ring]
    if possible or m.get("game") == "search":
        rec.log(
            f"{base}/possible",
            rr.LineStrips2D(possible, colors=[(255, 140, 0)]) if possible else rr.Clear(recursive=False),
        )
    if m.get("seen_by"):
        rec.log(f"{base}/alert", rr.TextLog(f"{agent} seen by {', '.join(m['seen_by'])}"))
    if m.get("uncertain"):
        rec.log(f"{base}/alert", rr.TextLog(f"{agent}: uncertain, the answer at the reports would differ"))
    reports = m.get("reports", [])
    if reports:
        points = [to_local(r["lat"], r["lon"]) for r in reports]
        drawn = markers.draw([(r["agent"], p) for r, p in zip(reports, points)])
        for shape, archetype in drawn.items():
            rec.log(f"{base}/agents/{shape}s", archetype)
        others = [(r, p) for r, p in zip(reports, points) if r["agent"] != agent and r.get("radius")]
        if others:
            disks = [_disk(p, r["radius"]) for r, p in others]
            colours = [_paler(markers.colour(r["agent"])) for r, _ in others]
            ages = [f"{r['agent']} {max(m['t'] - r['t'], 0.0):.1f} s ago" for r, _ in others]
            rec.log(f"{base}/disks", rr.LineStrips2D(disks, colors=colours, labels=ages))
            for (r, _), ring, colour in zip(others, disks, colours):
                rec.log(f"ground/uncertainty/{r['agent']}", rr.LineStrips2D([ring], colors=[colour]))
        predicted = [r for r in reports if r.get("predicted") and r.get("ellipse")]
        if predicted:
            ellipses = [_ellipse(to_local(r["predicted"][1], r["predicted"][0]), *r["ellipse"]) for r in predicted]
            colours = [_paler(markers.colour(r["agent"])) for r in predicted]
            labels = [f"{r['agent']} now" for r in predicted]
            rec.log(f"{base}/predicted", rr.LineStrips2D(ellipses, colors=colours, labels=labels))
            for r, ring, colour in zip(predicted, ellipses, colours):
                rec.log(f"ground/prediction/{r['agent']}", rr.LineStrips2D([ring], colors=[colour]))
        me = next((p for p, r in zip(points, reports) if r["agent"] == agent), None)
        if me is not None and m.get("heading") is not None:
            b = np.radians(m["heading"])
            arrow = 4 * markers.size * np.array([np.sin(b), np.cos(b)])
            rec.log(f"{base}/heading", rr.Arrows2D(origins=[me], vectors=[arrow], colors=[markers.colour(agent)]))
    if m.get("value") is not None:
        rec.log(f"game/value/{agent}", rr.Scalars(m["value"]))


def _disk(centre, radius: float, sides: int = 48) -> np.ndarray:
    """A circle as a closed line of ``sides`` segments."""
    angles = np.linspace(0.0, 2 * np.pi, sides + 1)
    return np.asarray(centre) + radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)


def _ellipse(centre, major: float, minor: float, bearing: float, sides: int = 48) -> np.ndarray:
    """An ellipse as a closed line: semi-axes in metres, the major axis's
    bearing in degrees clockwise from north."""
    b = np.radians(bearing)
    along, across = np.array([np.sin(b), np.cos(b)]), np.array([np.cos(b), -np.sin(b)])
    angles = np.linspace(0.0, 2 * np.pi, sides + 1)[:, None]
    return np.asarray(centre) + major * np.cos(angles) * along + minor * np.sin(angles) * across


def _state_line(state: dict) -> str:
    """A referee state as the log shows it: ``ended: attacker wins (attacker returned the flag)``."""
    line = state["phase"]
    if state.get("winner"):
        line += f": {state['winner']} wins"
    if state.get("reason"):
        line += f" ({state['reason']})"
    return line
