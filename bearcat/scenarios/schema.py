"""Scenario files: TOML in, a checked ``Scenario`` out.

A scenario names a map, a game with its rules, the network profile, and the
agents with where they start, how fast they can go, how they behave and
whether their phone shows reachability guidance::

    [scenario]
    name = "fake-out"
    map = "field-50"
    game = "ctf"                 # ctf | reach-avoid | pursuit | a game of one's own (scenarios.game)
    time_limit = 60.0            # s of game time
    netem = "wifi"               # a profile of netem/profiles.toml
    transport = "tcp"            # live runs: fixes and guidance over tcp (retransmitted) or udp (lost)
    seed = 0

    [rules]                      # per game: CtfRules, ReachAvoidRules, PursuitRules
    capture_radius = 2.5

    [guidance]
    rate = 10.0                  # Hz, per agent
    method = "calibrated"        # none | worst-case | calibrated | one's own: what aided phones are told
    options = {}                 # the method's options
    alpha = 0.01                 # calibrated: the share of goes the margin lets be wrong
    confidence = 0.95            # worst-case: of a fix's GPS error circle the disks hold (0: its age only)

    [[agent]]
    id = "attacker"
    team = "attacker"
    start = [25.0, 30.0]         # map metres (east, north)
    speed = 3.0                  # top speed, m/s on full-speed terrain
    behaviour = "fake-out"       # a built-in, or one's own: "file.py:Class", "module:Class" or an installed name
    options = { spread = 80.0 }  # the behaviour's options
    aided = true
    guidance = "none"            # optional: this agent's own method, instead of guidance.method
    guidance_options = {}        # its options

    [[uav]]                      # optional: quadrotors flying for a team (thesis 6.2)
    id = "q1"
    team = "attacker"
    start = [125.0, 12.0]        # where it takes off, map metres
    altitude = 20.0              # m above home
    camera_radius = 15.0         # r_q: the camera sees a disk this wide on the ground
    search = "reachability"      # reachability | lawnmower | nearest | a tasking policy of one's own
    search_options = {}          # the policy's options
    steer = "goto"               # goto | velocity (offboard setpoints)

    [supervision]                # optional: which peers a live run starts again (scenarios.supervision)
    max_restarts = 3

The Structs below are the schema: every key with its type, its bounds and
its default, declared once. msgspec checks a file against them; a second
pass checks what needs the map (starts, hold points and waypoints in the
free space, regions the rules name). Every error is one sentence naming
the file and the key path, list indices counted from 0, such as
``fake-out.toml: agent[0].behaviour: 'fakeout' is not one of ...``.
"""

from __future__ import annotations

import tomllib
import typing
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, get_args

import msgspec
import tomli_w
from msgspec import Meta
from shapely.geometry import Polygon

from bearcat.agents.ground_station.guidance.method import GUIDANCE_METHODS, GuidanceMethod
from bearcat.agents.ground_station.tasking import TASKING
from bearcat.agents.human.behaviour import BEHAVIOURS, COMMITS
from bearcat.agents.options import Angle, Options, Period, Point
from bearcat.agents.registry import Entry, PluginError, Registry
from bearcat.agents.uav.agent import Failsafe, Steering
from bearcat.bus.messages import Name
from bearcat.maps import Map, MapError, load_map
from bearcat.maps.model import check_polygonal
from bearcat.netem.profiles import load_profiles
from bearcat.scenarios.faults import Fault, check_faults
from bearcat.scenarios.game import GAMES, Game
from bearcat.scenarios.supervision import Supervision
from bearcat.solvers.levelset.devices import DEVICES
from bearcat.validation import Invalid, convert, not_one_of

MAX_CELLS = 2000
"""Most cells across the map that ``rules.spacing`` may ask of the fast-marching grid."""

if TYPE_CHECKING:
    ProfileName = str  # read from the profiles file: checked when a scenario is read
    Device = str  # where sets are solved: one of solvers.levelset.devices.DEVICES
else:
    ProfileName = Literal[tuple(load_profiles())]
    Device = Literal[DEVICES]
Ablation = Literal["prediction", "bias", "manoeuvre", "calibration", "belief"]
ABLATIONS: tuple[Ablation, ...] = get_args(Ablation)
"""Parts of calibrated guidance a study may switch off, to measure what each
gives: ``prediction`` (the trackers' beliefs stay at each player's latest
fix instead of going on to now), ``bias`` (the trackers take the GPS error
for white noise of the same size, with no bias state), ``manoeuvre`` (one
walking mode: a feint does not widen the prediction), ``calibration`` (the
attacker's go takes the tracker's own margin, not the calibrated one) and
``belief`` (the defender steers by the plain heading at the prediction, not
by a quantile over its belief)."""
Transport = Literal["tcp", "udp"]
TRANSPORTS: tuple[Transport, ...] = get_args(Transport)
"""How best-effort messages (fixes, guidance) travel in live runs; reliable ones always go over tcp."""
Ring = Annotated[tuple[Point, ...], Meta(min_length=3, description="a polygon of at least 3 [east, north] points")]
Rate = Annotated[float, Meta(ge=0.01, le=50.0, extra={"unit": "Hz"})]
Radius = Annotated[float, Meta(gt=0.0, le=1000.0, extra={"unit": "m"})]
WalkingSpeed = Annotated[float, Meta(gt=0.0, le=15.0, extra={"unit": "m/s"})]
"""A person's top speed: a sprinter peaks at 12.4 m/s."""


class ScenarioError(ValueError):
    """A scenario that cannot be run; the text names the file and the key."""


class _Table(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """A TOML table: its keys are exactly the fields."""


# ---------------------------------------------------------------- players

PluginName = Annotated[
    str,
    Meta(
        min_length=1,
        max_length=300,
        description="a plug-in's name, module:attribute or file.py:attribute",
    ),
]


class AgentSpec(_Table, frozen=True):
    """A person: where they start, how fast they go, how they decide
    (``behaviour``, a plug-in of ``BEHAVIOURS``, with its ``options``) and
    how their phone guides them."""

    id: Name
    team: Name  # one of its game's two teams
    start: Point
    speed: WalkingSpeed
    behaviour: PluginName
    options: dict[str, Any] = {}  # read into the behaviour's options type (Scenario.behaviour_of)
    aided: bool = True
    guidance: PluginName | None = None  # this agent's guidance method; None: the scenario's guidance.method
    guidance_options: dict[str, Any] = {}  # read into its options type (Scenario.guidance_of)
    fix_rate: Rate = 1.0
    reaction: Annotated[float, Meta(ge=0.0, le=10.0, extra={"unit": "s"})] = 0.4  # from a display change to a turn
    heading_error: Angle = 10.0  # standard deviation of following a displayed heading
    # How long, in live runs, the behaviour may take to decide before its
    # answer is dropped; None: a quarter of the walker's tick.
    budget: Annotated[float, Meta(gt=0.0, le=10.0, extra={"unit": "s"})] | None = None


@dataclass(frozen=True)
class Plugged:
    """A plug-in a scenario chose: its registry ``entry`` and the ``options`` read into its type."""

    entry: Entry
    options: msgspec.Struct


class UavSpec(_Table, frozen=True):
    """A quadrotor flying for ``team``: its take-off point, altitude above
    home, camera footprint radius r_q, limits, how the ground station tasks
    it, and what it does when it loses the ground station."""

    id: Name
    team: Name  # one of its game's two teams
    start: Point
    altitude: Annotated[float, Meta(gt=0.0, le=500.0, extra={"unit": "m"})] = 20.0
    camera_radius: Radius = 15.0
    speed: Annotated[float, Meta(gt=0.0, le=40.0, extra={"unit": "m/s"})] = 8.0
    accel: Annotated[float, Meta(gt=0.0, le=20.0, extra={"unit": "m/s^2"})] = 3.0
    search: PluginName = "reachability"  # the tasking policy: a plug-in of TASKING
    search_options: dict[str, Any] = {}  # read into the policy's options type (Scenario.tasking_of)
    failsafe: Failsafe = "hold"
    link_timeout: Period = 5.0
    fix_rate: Rate = 2.0
    steer: Steering = "goto"


# ---------------------------------------------------------------- rules per game

Horizon = Annotated[float, Meta(gt=0.0, le=3600.0, extra={"unit": "s"})]
Spacing = Annotated[float, Meta(gt=0.0, le=100.0, extra={"unit": "m"})]


class CtfRules(_Table, frozen=True):
    """Unset radius and times are derived from the map and the speeds (``maps.ctf_rules.default_rules``)."""

    capture_radius: Radius | None = None
    stages: Literal["return", "both"] = "return"
    grid: Annotated[int, Meta(ge=9, le=201)] = 45
    # The grid of the sets a live run starts on while the ``grid`` sets are
    # not yet solved; unset: derived from the capture radius
    # (``maps.ctf_rules.provisional_grid``), 0: wait for the ``grid`` sets.
    provisional_grid: Annotated[int, Meta(ge=0, le=201)] | None = None
    capture_time: Horizon | None = None
    return_time: Horizon | None = None
    visibility: Literal["full", "line-of-sight"] = "full"
    # Where the sets are solved (solvers.levelset.devices): "auto" takes a GPU when
    # numba-cuda finds one; the sets, and their cache entries, are the same.
    device: Device = "auto"


class ReachAvoidRules(_Table, frozen=True):
    capture_radius: Radius | None = None
    targets: Annotated[tuple[Annotated[str, Meta(min_length=1)], ...], Meta(min_length=1)] = ("flag", "home")
    spacing: Spacing | None = None


class PursuitRules(_Table, frozen=True):
    capture_radius: Radius = 0.5
    spacing: Spacing | None = None
    strategy: Literal["area", "pure"] = "area"


# ---------------------------------------------------------------- the file


class ScenarioTable(_Table, frozen=True):
    name: Name  # names the game on the bus
    map: Annotated[str, Meta(min_length=1)]
    game: PluginName  # a plug-in of GAMES: ctf, reach-avoid, pursuit, or one's own
    time_limit: Annotated[float, Meta(gt=0.0, le=86400.0, extra={"unit": "s"})]
    description: str = ""
    netem: ProfileName = "ideal"
    transport: Transport = "tcp"
    seed: Annotated[int, Meta(ge=0)] = 0
    dead_zones: Annotated[tuple[Ring, ...], Meta(description="a list of polygons of [east, north] points")] = ()
    # How long a silent peer's session lives before its liveliness vanishes
    # (Zenoh's link lease in live runs, the same rule in simulation): long
    # enough that a loaded machine or a stalled cellular link does not trip it.
    lease: Annotated[float, Meta(ge=0.5, le=120.0, extra={"unit": "s"})] = 10.0


class GuidanceTable(_Table, frozen=True):
    rate: Rate = 10.0
    # What aided phones are told, a plug-in of GUIDANCE_METHODS; None: its
    # game's default (its class's default_guidance): calibrated for
    # capture-the-flag, worst-case for reach-avoid, none for pursuit.
    method: PluginName | None = None
    options: dict[str, Any] = {}  # read into the method's options type (Scenario.guidance_of)
    # How long, in live runs, a method may take to answer before its
    # answer is dropped; None: a quarter of the guidance period.
    budget: Annotated[float, Meta(gt=0.0, le=10.0, extra={"unit": "s"})] | None = None
    # worst-case: the share of a fix's GPS error the disks hold (the radius
    # of its 95 % circle by default); 0: only how far an agent may have
    # moved since its fix.
    confidence: Annotated[float, Meta(ge=0.0, le=0.999)] = 0.95
    # calibrated: the attacker's go holds when the value plus the margin
    # measured at this level is below zero, so at most this share of goes
    # are wrong about the state they were made in.
    alpha: Annotated[float, Meta(gt=0.0, le=0.5)] = 0.01
    # calibrated: the share of the tracker's belief the defender's heading
    # is allowed to lose against; 0.5 acts on the median value.
    defender_quantile: Annotated[float, Meta(gt=0.0, lt=1.0)] = 0.5
    # calibrated: parts switched off (ABLATIONS), for studies of what each gives.
    ablate: tuple[Ablation, ...] = ()


class ScenarioFile(_Table, frozen=True):
    scenario: ScenarioTable
    agent: Annotated[tuple[AgentSpec, ...], Meta(min_length=1, description="at least one [[agent]] table")]
    rules: dict[str, Any] = {}
    guidance: GuidanceTable = GuidanceTable()
    uav: tuple[UavSpec, ...] = ()
    fault: tuple[Fault, ...] = ()
    supervision: Supervision = Supervision()


@dataclass(frozen=True)
class Scenario:
    name: str
    source: str
    map: Map
    game: str
    time_limit: float
    netem: str
    transport: str  # how best-effort messages travel in live runs: "tcp" or "udp"
    seed: int
    rules: msgspec.Struct  # read into its game's rules type (game_entry.options_type)
    guidance_rate: float
    guidance_confidence: float
    agents: tuple[AgentSpec, ...]
    description: str
    text: str  # the TOML it was read from, served to peers that ask
    dead_zones: tuple[tuple[tuple[float, float], ...], ...]
    uavs: tuple[UavSpec, ...]
    game_entry: Entry  # the game's entry of GAMES, whose factory makes it (cast.build_cast)
    lease: float = 10.0  # s a silent peer's liveliness outlives it
    faults: tuple = ()  # the scenario's own fault plan (scenarios.faults)
    alpha: float = 0.01  # calibrated: the false-go share the margin allows
    defender_quantile: float = 0.5  # calibrated: the share of the belief the defender may lose against
    ablate: tuple[str, ...] = ()  # calibrated: parts switched off (ABLATIONS)
    behaviours: dict[str, Plugged] = field(default_factory=dict)  # agent -> its behaviour, options read
    tasking: dict[str, Plugged] = field(default_factory=dict)  # UAV -> its tasking policy, options read
    guidance: dict[str, Plugged] = field(default_factory=dict)  # agent -> its guidance method, options read
    guidance_budget: float | None = None  # s a method may take in live runs; None: a quarter of the period
    supervision: Supervision = field(default_factory=Supervision)  # which peers a live run starts again, how soon
    directory: Path | None = None  # the folder of the scenario's file, which file.py:attribute plug-ins are in

    def behaviour_of(self, agent: str) -> Plugged:
        """How ``agent`` decides: its behaviour's entry, with the options the scenario gives it."""
        return self.behaviours[agent]

    def guidance_of(self, agent: str) -> Plugged:
        """What ``agent``'s phone is told: its guidance method's entry, with the options the scenario gives it."""
        return self.guidance[agent]

    def tasking_of(self, uav: str) -> Plugged:
        """How the ground station tasks ``uav``: its policy's entry, with the options the scenario gives it."""
        return self.tasking[uav]

    @property
    def committing(self) -> frozenset[str]:
        """The agents whose behaviour commits to a run at some moment (``AGENT.goes``)."""
        return frozenset(a for a, chosen in self.behaviours.items() if chosen.entry.has(COMMITS))

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
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{path} is not UTF-8 text (byte {exc.start} is {exc.object[exc.start]:#04x})") from None
    except OSError as exc:
        raise ScenarioError(f"{path} cannot be read: {exc.strerror}") from None
    return parse_scenario(text, source=str(path), directory=path.resolve().parent)


def parse_scenario(
    text: str, source: str = "<scenario>", *, game_map: Map | None = None, directory: Path | None = None
) -> Scenario:
    """The scenario in ``text``; ``game_map``, if given, stands for the map it
    names (a peer that fetched both from the ground station); ``directory``
    is the folder a ``file.py:attribute`` plug-in it names is relative to
    (None: the working directory)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source} is not valid TOML: {exc}") from None
    except RecursionError:
        raise ScenarioError(f"{source} nests arrays or tables too deeply to be a scenario") from None
    try:
        _check_renamed(data)
        file = convert(data, ScenarioFile)
        head = file.scenario
        try:
            game = GAMES.get(head.game, directory)
        except PluginError as exc:
            raise Invalid("scenario.game", str(exc)) from None
        rules = convert(file.rules, game.options_type, at="rules")
        declared = typing.cast(type[Game], game.factory)
        if game_map is None:
            try:
                game_map = load_map(head.map)
            except MapError as exc:
                raise Invalid("scenario.map", str(exc)) from None
        behaviours = _plugged(BEHAVIOURS, "agent", [(a.id, a.behaviour, a.options) for a in file.agent], directory)
        tasking = _plugged(TASKING, "uav", [(u.id, u.search, u.search_options) for u in file.uav], directory)
        guidance = _guidance(file, declared, directory)
        _check_against(file, rules, game_map, behaviours, declared.teams)
        text = _located(text, data, directory)
    except (Invalid, MapError) as exc:
        raise ScenarioError(f"{source}: {exc}") from None
    return Scenario(
        name=head.name,
        source=source,
        map=game_map,
        game=head.game,
        time_limit=head.time_limit,
        netem=head.netem,
        transport=head.transport,
        seed=head.seed,
        rules=rules,
        guidance_rate=file.guidance.rate,
        guidance_confidence=file.guidance.confidence,
        alpha=file.guidance.alpha,
        defender_quantile=file.guidance.defender_quantile,
        ablate=tuple(dict.fromkeys(file.guidance.ablate)),
        agents=file.agent,
        description=head.description,
        text=text,
        dead_zones=head.dead_zones,
        uavs=file.uav,
        lease=head.lease,
        faults=file.fault,
        game_entry=game,
        behaviours=behaviours,
        tasking=tasking,
        guidance=guidance,
        guidance_budget=file.guidance.budget,
        supervision=file.supervision,
        directory=directory,
    )


def _located(text: str, data: dict, directory: Path | None) -> str:
    """``text``, or where it names a plug-in by a file relative to its
    folder, the same scenario naming that file by its absolute path: the
    text a run keeps and serves, which its peers and checker read from
    other folders."""
    named = [(data["scenario"], "game"), (data.get("guidance", {}), "method")]
    named += [(agent, key) for agent in data["agent"] for key in ("behaviour", "guidance")]
    named += [(uav, "search") for uav in data.get("uav", ())]
    relative = [
        (table, key)
        for table, key in named
        if key in table
        and table[key].rpartition(":")[0].endswith(".py")
        and not Path(table[key].rpartition(":")[0]).is_absolute()
    ]
    if not relative:
        return text
    for table, key in relative:
        where, _, attribute = table[key].rpartition(":")
        table[key] = f"{((directory or Path.cwd()) / where).resolve()}:{attribute}"
    return tomli_w.dumps(data)


def _plugged(registry: Registry, kind: str, named, directory: Path | None) -> dict[str, Plugged]:
    """For each (id, plug-in, options) of the ``kind`` tables, its entry from
    ``registry`` with the options read into its type."""
    key, options_key = {"agent": ("behaviour", "options"), "uav": ("search", "search_options")}[kind]
    return {
        name: _plug(registry, ref, options, directory, f"{kind}[{k}].{key}", f"{kind}[{k}].{options_key}")
        for k, (name, ref, options) in enumerate(named)
    }


def _plug(registry: Registry, ref: str, options: dict, directory: Path | None, at: str, options_at: str) -> Plugged:
    """The entry ``ref`` names in ``registry`` (a scenario's key ``at``), with ``options`` read into its type."""
    try:
        entry = registry.get(ref, directory)
    except PluginError as exc:
        raise Invalid(at, str(exc)) from None
    return Plugged(entry, convert(options, entry.options_type, at=options_at))


def _guidance(file: ScenarioFile, game: type[Game], directory: Path | None) -> dict[str, Plugged]:
    """Each agent's guidance method (its own, else the scenario's, else its
    ``game``'s default), with its options, refused where it builds on a
    form of answer the game does not give."""
    table = file.guidance
    method = table.method or game.default_guidance
    shared = _plug(GUIDANCE_METHODS, method, table.options, directory, "guidance.method", "guidance.options")
    chosen = {}
    for k, agent in enumerate(file.agent):
        at = f"agent[{k}].guidance"
        own = agent.guidance is not None
        plugged = shared
        if agent.guidance is not None:
            plugged = _plug(GUIDANCE_METHODS, agent.guidance, agent.guidance_options, directory, at, f"{at}_options")
        missing = typing.cast(type[GuidanceMethod], plugged.entry.factory).needs - game.answers
        if missing:
            raise Invalid(
                at if own else "guidance.method",
                f"guidance method {plugged.entry.name!r} builds on {' and '.join(sorted(missing))} answers, "
                f"which a {file.scenario.game} game does not give (it gives {', '.join(sorted(game.answers))})",
            )
        chosen[agent.id] = plugged
    return chosen


def _check_renamed(data: dict) -> None:
    """A key an older bearcat read, named with what replaced it."""
    renamed = {
        "robust": '{}: "worst-case" for true, "none" for false',
        "uncertainty": "{}, which takes the same names (none, worst-case, calibrated) and methods of one's own",
    }
    guidance = data.get("guidance")
    agents = data.get("agent")
    tables = [("guidance.", "method", guidance)]
    listed = agents if isinstance(agents, list) else ()
    tables += [(f"agent[{k}].", "guidance", agent) for k, agent in enumerate(listed)]
    for prefix, new, table in tables:
        for old, how in renamed.items():
            if isinstance(table, dict) and old in table:
                raise Invalid(f"{prefix}{old}", "was replaced by " + how.format(prefix + new))


def _check_against(
    file: ScenarioFile, rules, game_map: Map, behaviours: dict[str, Plugged], teams: tuple[str, str]
) -> None:
    """What needs the game and the map: teams, places, regions, grid sizes, who plays."""
    game = file.scenario.game
    sides: list[tuple[str, str]] = [(f"agent[{k}]", a.team) for k, a in enumerate(file.agent)]
    sides += [(f"uav[{k}]", u.team) for k, u in enumerate(file.uav)]
    for where, team in sides:
        if team not in teams:
            raise Invalid(f"{where}.team", f"{not_one_of(team, teams)} (the teams of a {game} game)")
    for k, agent in enumerate(file.agent):
        game_map.check_position(agent.start, f"agent[{k}].start")
        options = behaviours[agent.id].options
        for key, point in options.places() if isinstance(options, Options) else ():
            game_map.check_position(point, f"agent[{k}].options.{key}")
    xmin, ymin, xmax, ymax = game_map.bounds
    for k, uav in enumerate(file.uav):
        x, y = uav.start
        if not (xmin <= x <= xmax and ymin <= y <= ymax):
            raise Invalid(
                f"uav[{k}].start",
                f"{list(uav.start)} is off map {game_map.name} ({xmin:g}..{xmax:g} x {ymin:g}..{ymax:g} m)",
            )
    for k, ring in enumerate(file.scenario.dead_zones):
        check_polygonal(Polygon(ring), f"scenario.dead_zones[{k}]")
    for name in getattr(rules, "targets", ()):
        if name not in game_map.regions:
            regions = ", ".join(game_map.regions) or "none"
            raise Invalid("rules.targets", f"map {game_map.name} has no region {name!r}; its regions are {regions}")
    spacing = getattr(rules, "spacing", None)
    side = max(xmax - xmin, ymax - ymin)
    if spacing is not None and not 2 <= side / spacing <= MAX_CELLS:
        raise Invalid(
            "rules.spacing",
            f"{spacing:g} m makes {side / spacing:.0f} cells across map {game_map.name} ({side:g} m); "
            f"2 to {MAX_CELLS} are allowed",
        )
    committing = [a for a, chosen in behaviours.items() if chosen.entry.has(COMMITS)]
    check_faults(file.fault, file.agent, file.uav, committing)
    ids = [a.id for a in file.agent] + [u.id for u in file.uav]
    twice = sorted({i for i in ids if ids.count(i) > 1})
    if twice:
        raise Invalid("", f"agent id {twice[0]!r} is used twice")
    for team in teams:
        if not any(a.team == team for a in file.agent):
            raise Invalid("", f"a {game} game needs at least one agent of team {team!r}")
