"""Scenario files: TOML in, a checked ``Scenario`` out.

A scenario names a map, a game with its rules, the network profile, and the
agents with where they start, how fast they can go, how they behave and
whether their phone shows reachability guidance::

    [scenario]
    name = "fake-out"
    map = "field-50"
    game = "ctf"                 # ctf | reach-avoid | pursuit
    time_limit = 60.0            # s of game time
    netem = "wifi"               # a profile of netem/profiles.toml
    seed = 0

    [rules]                      # per game; see RULE_KEYS
    capture_radius = 2.5

    [guidance]
    rate = 10.0                  # Hz, per agent

    [[agent]]
    id = "attacker"
    team = "attacker"
    start = [25.0, 30.0]         # map metres (east, north)
    speed = 3.0                  # top speed, m/s on full-speed terrain
    behaviour = "fake-out"
    aided = true

    [[uav]]                      # optional: quadrotors flying for a team (thesis 6.2)
    id = "q1"
    team = "attacker"
    start = [125.0, 12.0]        # where it takes off, map metres
    altitude = 20.0              # m above home
    camera_radius = 15.0         # r_q: the camera sees a disk this wide on the ground
    search = "reachability"      # reachability | lawnmower | nearest
    steer = "goto"               # goto | velocity (offboard setpoints)

Every error is one sentence naming the file and the key, such as
``fake-out.toml: agent[1].behaviour 'fakeout' is not one of ...``.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from bearcat.agents.uav.agent import FAILSAFES, STEERING
from bearcat.maps import Map, MapError, load_map
from bearcat.netem.profiles import ProfileError, load_profile

GAMES = ("ctf", "reach-avoid", "pursuit")
TEAMS = {"ctf": ("attacker", "defender"), "reach-avoid": ("attacker", "defender"), "pursuit": ("evader", "pursuer")}
BEHAVIOURS = ("follow-guidance", "direct", "fake-out", "go-no-go", "waypoints", "patrol", "keyboard")
SEARCHES = ("reachability", "lawnmower", "nearest")

# Per game, the rules keys with their defaults (None: derived from the map and speeds).
RULE_KEYS = {
    "ctf": {
        "capture_radius": None,
        "stages": "return",
        "grid": 45,
        "capture_time": None,
        "return_time": None,
        "visibility": "full",
    },
    "reach-avoid": {"capture_radius": None, "targets": ["flag", "home"], "spacing": None},
    "pursuit": {"capture_radius": 0.5, "spacing": None, "strategy": "area"},
}
# Per behaviour, its option keys and defaults.
BEHAVIOUR_OPTIONS = {
    "follow-guidance": {},
    "direct": {"standoff": 6.0, "share": 0.5, "lead": 1.5},
    "fake-out": {"turn_every": 1.5, "spread": 100.0, "margin": 0.0},
    "go-no-go": {"hold": None, "fresh": 2.0, "margin": 0.0, "flee": 0.0},
    "waypoints": {"points": None, "loop": False},
    "patrol": {"points": None, "standoff": 6.0, "share": 0.5, "lead": 1.5, "memory": 5.0, "wander": False},
    "keyboard": {},
}
_AGENT_KEYS = {
    "id",
    "team",
    "start",
    "speed",
    "behaviour",
    "aided",
    "fix_rate",
    "reaction",
    "heading_error",
    "options",
}


# UAV keys and their defaults (None: required).
UAV_KEYS = {
    "id": None,
    "team": None,
    "start": None,
    "altitude": 20.0,
    "camera_radius": 15.0,
    "speed": 8.0,
    "accel": 3.0,
    "search": "reachability",
    "failsafe": "hold",
    "link_timeout": 5.0,
    "fix_rate": 2.0,
    "steer": "goto",
}


class ScenarioError(ValueError):
    """A scenario that cannot be run; the text names the file and the key."""


@dataclass(frozen=True)
class AgentSpec:
    id: str
    team: str
    start: tuple[float, float]
    speed: float
    behaviour: str
    aided: bool = True
    fix_rate: float = 1.0  # Hz of GPS fixes
    reaction: float = 0.4  # s from a display change to the body turning
    heading_error: float = 10.0  # degrees, standard deviation of following a displayed heading
    options: dict = field(default_factory=dict)


@dataclass(frozen=True)
class UavSpec:
    """A quadrotor flying for ``team``: its take-off point, altitude above
    home, camera footprint radius r_q, limits, how the ground station tasks
    it, and what it does when it loses the ground station."""

    id: str
    team: str
    start: tuple[float, float]
    altitude: float = 20.0
    camera_radius: float = 15.0
    speed: float = 8.0
    accel: float = 3.0
    search: str = "reachability"
    failsafe: str = "hold"
    link_timeout: float = 5.0
    fix_rate: float = 2.0
    steer: str = "goto"


@dataclass(frozen=True)
class Scenario:
    name: str
    source: str
    map: Map
    game: str
    time_limit: float
    netem: str
    seed: int
    rules: dict
    guidance_rate: float
    agents: tuple[AgentSpec, ...]
    description: str = ""
    text: str = ""  # the TOML it was read from, served to peers that ask
    dead_zones: tuple[tuple[tuple[float, float], ...], ...] = ()
    uavs: tuple[UavSpec, ...] = ()

    def uav_of(self, team: str) -> list[UavSpec]:
        return [u for u in self.uavs if u.team == team]

    def team(self, name: str) -> list[AgentSpec]:
        return [a for a in self.agents if a.team == name]

    def agent(self, agent_id: str) -> AgentSpec:
        for a in self.agents:
            if a.id == agent_id:
                return a
        raise ScenarioError(f"{self.source}: there is no agent {agent_id!r}; the agents are {', '.join(self.ids)}")

    @property
    def ids(self) -> list[str]:
        return [a.id for a in self.agents]


def builtin_dir():
    return resources.files("bearcat.scenarios") / "data"


def list_scenarios() -> list[str]:
    return sorted(p.name[:-5] for p in builtin_dir().iterdir() if p.name.endswith(".toml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A built-in scenario by name, or a TOML file."""
    if isinstance(name_or_path, str) and name_or_path in list_scenarios():
        text = (builtin_dir() / f"{name_or_path}.toml").read_text(encoding="utf-8")
        return parse_scenario(text, source=f"{name_or_path}.toml")
    path = Path(name_or_path)
    if not path.exists():
        raise ScenarioError(
            f"there is no scenario {str(name_or_path)!r}: not a built-in one ({', '.join(list_scenarios())}) nor a file"
        )
    return parse_scenario(path.read_text(encoding="utf-8"), source=str(path))


def parse_scenario(text: str, source: str = "<scenario>", *, game_map: Map | None = None) -> Scenario:
    """The scenario in ``text``; ``game_map``, if given, stands for the map it
    names (a peer that fetched both from the ground station)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source} is not valid TOML: {exc}") from None
    c = _Checker(source)
    c.only(data, {"scenario", "rules", "guidance", "agent", "uav"}, "")
    head = c.table(data, "scenario", "")
    c.only(head, {"name", "description", "map", "game", "time_limit", "netem", "seed", "dead_zones"}, "scenario")
    game = c.choice(head, "game", GAMES, "scenario")
    if game_map is None:
        try:
            game_map = load_map(c.text(head, "map", "scenario"))
        except MapError as exc:
            raise ScenarioError(f"{source}: scenario.map: {exc}") from None
    netem = head.get("netem", "ideal")
    try:
        load_profile(netem)
    except ProfileError as exc:
        raise ScenarioError(f"{source}: scenario.netem: {exc}") from None
    rules = _rules(c, c.table(data, "rules", "", required=False), game, game_map)
    guidance = c.table(data, "guidance", "", required=False)
    c.only(guidance, {"rate"}, "guidance")
    raw_agents = data.get("agent")
    if not isinstance(raw_agents, list) or not raw_agents:
        raise ScenarioError(f"{source}: a scenario needs at least one [[agent]]")
    agents = tuple(_agent(c, raw, k, game, game_map) for k, raw in enumerate(raw_agents))
    raw_uavs = data.get("uav", [])
    if not isinstance(raw_uavs, list):
        c.fail("uav must be an array of tables: [[uav]]")
    uavs = tuple(_uav(c, raw, k, game, game_map) for k, raw in enumerate(raw_uavs))
    ids = [a.id for a in agents] + [u.id for u in uavs]
    if len(set(ids)) != len(ids):
        twice = sorted({i for i in ids if ids.count(i) > 1})
        raise ScenarioError(f"{source}: agent id {twice[0]!r} is used twice")
    for team in TEAMS[game]:
        if not any(a.team == team for a in agents):
            raise ScenarioError(f"{source}: a {game} game needs at least one agent of team {team!r}")
    zones = []
    for k, ring in enumerate(head.get("dead_zones", [])):
        zones.append(tuple(c.point(p, f"scenario.dead_zones[{k}]") for p in ring))
        if len(zones[-1]) < 3:
            raise ScenarioError(f"{source}: scenario.dead_zones[{k}] needs at least 3 points")
    name = c.text(head, "name", "scenario")
    if not name.replace("-", "").replace("_", "").isalnum() or not name.isascii() or len(name) > 64:
        c.fail(f"scenario.name {name!r} must be up to 64 letters, digits, '-' or '_' (it names the game on the bus)")
    return Scenario(
        name=name,
        source=source,
        map=game_map,
        game=game,
        time_limit=c.number(head, "time_limit", "scenario", positive=True),
        netem=netem,
        seed=int(c.integer(head, "seed", "scenario", default=0)),
        rules=rules,
        guidance_rate=c.number(guidance, "rate", "guidance", default=10.0, positive=True),
        agents=agents,
        description=str(head.get("description", "")),
        text=text,
        dead_zones=tuple(zones),
        uavs=uavs,
    )


def _agent(c: _Checker, raw, k: int, game: str, game_map: Map) -> AgentSpec:
    at = f"agent[{k}]"
    if not isinstance(raw, dict):
        raise ScenarioError(f"{c.source}: {at} must be a table")
    c.only(raw, _AGENT_KEYS, at)
    agent_id = c.text(raw, "id", at)
    if not agent_id.replace("-", "").replace("_", "").isalnum() or not agent_id.isascii() or len(agent_id) > 64:
        raise ScenarioError(f"{c.source}: {at}.id {agent_id!r} must be letters, digits, '-' or '_'")
    team = c.choice(raw, "team", TEAMS[game], at)
    start = c.point(raw.get("start"), f"{at}.start")
    try:
        game_map.check_position(start, f"{at}.start")
    except MapError as exc:
        raise ScenarioError(f"{c.source}: {exc}") from None
    behaviour = c.choice(raw, "behaviour", BEHAVIOURS, at)
    options = dict(BEHAVIOUR_OPTIONS[behaviour])
    given = c.table(raw, "options", at, required=False)
    c.only(given, set(options), f"{at}.options")
    options.update(given)
    missing = [key for key, value in options.items() if value is None]
    if missing:
        raise ScenarioError(f"{c.source}: {at}.options.{missing[0]} is required by behaviour {behaviour!r}")
    if behaviour == "go-no-go":
        options["hold"] = c.point(options["hold"], f"{at}.options.hold")
        options["fresh"] = c.number(options, "fresh", f"{at}.options", positive=True)
        options["margin"] = c.number(options, "margin", f"{at}.options")
        options["flee"] = c.number(options, "flee", f"{at}.options")
    elif behaviour in ("waypoints", "patrol"):
        points = options["points"]
        if not isinstance(points, list) or not points:
            c.fail(f"{at}.options.points must be a list of [east, north] points")
        for j, point in enumerate(points):
            try:
                game_map.check_position(c.point(point, f"{at}.options.points[{j}]"), f"{at}.options.points[{j}]")
            except MapError as exc:
                raise ScenarioError(f"{c.source}: {exc}") from None
        checked = {"points": [c.point(p, f"{at}.options.points[{j}]") for j, p in enumerate(points)]}
        if behaviour == "waypoints":
            checked["loop"] = c.boolean(options, "loop", f"{at}.options", default=False)
        else:
            checked.update({k: c.number(options, k, f"{at}.options") for k in ("standoff", "share", "lead", "memory")})
            checked["wander"] = c.boolean(options, "wander", f"{at}.options", default=False)
        options = checked
    elif behaviour == "direct":
        options = {k: c.number(options, k, f"{at}.options") for k in options}
    elif behaviour == "fake-out":
        options = {k: c.number(options, k, f"{at}.options", positive=k != "margin") for k in options}
    return AgentSpec(
        id=agent_id,
        team=team,
        start=start,
        speed=c.number(raw, "speed", at, positive=True),
        behaviour=behaviour,
        aided=c.boolean(raw, "aided", at, default=True),
        fix_rate=c.number(raw, "fix_rate", at, default=1.0, positive=True),
        reaction=c.number(raw, "reaction", at, default=0.4),
        heading_error=c.number(raw, "heading_error", at, default=10.0),
        options=options,
    )


def _uav(c: _Checker, raw, k: int, game: str, game_map: Map) -> UavSpec:
    at = f"uav[{k}]"
    if not isinstance(raw, dict):
        c.fail(f"{at} must be a table")
    c.only(raw, set(UAV_KEYS), at)
    given = {**UAV_KEYS, **raw}
    for key, value in given.items():
        if value is None:
            c.fail(f"{at}.{key} is required")
    uav_id = c.text(given, "id", at)
    if not uav_id.replace("-", "").replace("_", "").isalnum() or not uav_id.isascii() or len(uav_id) > 64:
        c.fail(f"{at}.id {uav_id!r} must be letters, digits, '-' or '_'")
    start = c.point(given["start"], f"{at}.start")
    xmin, ymin, xmax, ymax = game_map.bounds
    if not (xmin <= start[0] <= xmax and ymin <= start[1] <= ymax):
        c.fail(f"{at}.start {list(start)} is off map {game_map.name} ({xmin:g}..{xmax:g} x {ymin:g}..{ymax:g} m)")
    return UavSpec(
        id=uav_id,
        team=c.choice(given, "team", TEAMS[game], at),
        start=start,
        altitude=c.number(given, "altitude", at, positive=True),
        camera_radius=c.number(given, "camera_radius", at, positive=True),
        speed=c.number(given, "speed", at, positive=True),
        accel=c.number(given, "accel", at, positive=True),
        search=c.choice(given, "search", SEARCHES, at),
        failsafe=c.choice(given, "failsafe", FAILSAFES, at),
        link_timeout=c.number(given, "link_timeout", at, positive=True),
        fix_rate=c.number(given, "fix_rate", at, positive=True),
        steer=c.choice(given, "steer", STEERING, at),
    )


def _rules(c: _Checker, given: dict, game: str, game_map: Map) -> dict:
    rules = dict(RULE_KEYS[game])
    c.only(given, set(rules), "rules")
    rules.update(given)
    for key in ("capture_radius", "capture_time", "return_time", "spacing"):
        if rules.get(key) is not None:
            rules[key] = c.number(rules, key, "rules", positive=key != "capture_radius")
    if game == "ctf":
        rules["stages"] = c.choice(rules, "stages", ("return", "both"), "rules")
        rules["visibility"] = c.choice(rules, "visibility", ("full", "line-of-sight"), "rules")
        grid = rules["grid"]
        if isinstance(grid, bool) or not isinstance(grid, int) or not 9 <= grid <= 201:
            c.fail(f"rules.grid must be an integer from 9 to 201, got {grid!r}")
    elif game == "reach-avoid":
        targets = rules["targets"]
        if not isinstance(targets, list) or not targets:
            c.fail("rules.targets must be a list of region names of the map")
        for name in targets:
            if not isinstance(name, str) or name not in game_map.regions:
                c.fail(
                    f"rules.targets: map {game_map.name} has no region {name!r}; its regions are "
                    f"{', '.join(game_map.regions) or 'none'}"
                )
    else:
        rules["strategy"] = c.choice(rules, "strategy", ("area", "pure"), "rules")
    return rules


class _Checker:
    """Typed reads of TOML values whose errors name the file and the key."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, message: str):
        raise ScenarioError(f"{self.source}: {message}")

    @staticmethod
    def _name(at: str, key: str) -> str:
        return f"{at}.{key}" if at else key

    def only(self, table: dict, allowed: set[str], at: str) -> None:
        for key in table:
            if key not in allowed:
                self.fail(f"{self._name(at, key)} is not a known key; the keys there are {', '.join(sorted(allowed))}")

    def table(self, data: dict, key: str, at: str, required: bool = True) -> dict:
        if key not in data:
            if required:
                self.fail(f"[{self._name(at, key)}] is missing")
            return {}
        if not isinstance(data[key], dict):
            self.fail(f"{self._name(at, key)} must be a table")
        return data[key]

    def text(self, data: dict, key: str, at: str) -> str:
        value = data.get(key)
        if not isinstance(value, str) or not value:
            self.fail(f"{self._name(at, key)} must be a non-empty string, got {value!r}")
        return value

    def choice(self, data: dict, key: str, options, at: str) -> str:
        value = data.get(key)
        if value not in options:
            self.fail(f"{self._name(at, key)} {value!r} is not one of {', '.join(options)}")
        return value

    def number(self, data: dict, key: str, at: str, *, default=None, positive: bool = False) -> float:
        value = data.get(key, default)
        name = self._name(at, key)
        if value is None:
            self.fail(f"{name} is required")
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            self.fail(f"{name} must be a number, got {value!r}")
        if value < 0 or (positive and value == 0):
            self.fail(f"{name} must be {'positive' if positive else 'non-negative'}, got {value!r}")
        return float(value)

    def integer(self, data: dict, key: str, at: str, *, default=None) -> int:
        value = data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            self.fail(f"{self._name(at, key)} must be a non-negative integer, got {value!r}")
        return value

    def boolean(self, data: dict, key: str, at: str, *, default: bool) -> bool:
        value = data.get(key, default)
        if not isinstance(value, bool):
            self.fail(f"{self._name(at, key)} must be true or false, got {value!r}")
        return value

    def point(self, value, at: str) -> tuple[float, float]:
        if (
            not isinstance(value, list)
            or len(value) != 2
            or not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        ):
            self.fail(f"{at} must be [east, north] in metres, got {value!r}")
        return float(value[0]), float(value[1])
