"""Your own agents: what a plug-in implements, and the registries that find it.

A scenario names a behaviour of one's own in its agent's table::

    [[agent]]
    id = "attacker"
    behaviour = "sneaky.py:Sneaky"      # a file beside the scenario, or
    # behaviour = "mypkg.tactics:Sneaky"  an importable module, or
    # behaviour = "sneaky"                a name an installed distribution registers
    options = { patience = 4.0 }        # read into Sneaky.Options

and the class subclasses ``Behaviour``::

    import numpy as np
    from bearcat.plugins import Behaviour, Options

    class Sneaky(Behaviour):
        \"\"\"Creep toward the goal while nobody is near.\"\"\"

        class Options(Options, frozen=True):
            patience: float = 3.0

        def __init__(self, options, rng):
            self.patience = options.patience

        def decide(self, now, me, screen, situation):
            return situation.navigator.toward(situation.goal, me)

A guidance method is the same, a ``GuidanceMethod`` subclass that
``[guidance] method`` (or an agent's own ``guidance`` key) names, with its
``options``: its ``advise(view)`` answers what one aided phone is told,
an ``Advice``, from the latest fixes, the trackers' beliefs and the
game's advisor's own answers. A UAV tasking policy is a
``TaskingPolicy`` subclass a UAV's table names (``search =
"mine.py:Spiral"``, ``search_options = {...}``), whose ``next_point(uav,
view)`` answers where the UAV searches next.

A game of one's own subclasses ``Game``: its rules type, its two teams,
the forms of answer its advisor gives and its default guidance method,
and its referee, guidance service and people
(see the built-in ones in ``bearcat.scenarios.cast``); ``game = "..."``
names it.

A distribution makes a short name of any of these with an entry point::

    [project.entry-points."bearcat.behaviours"]
    sneaky = "mypkg.tactics:Sneaky"

    [project.entry-points."bearcat.guidance"]
    intercept = "mypkg.guidance:Intercept"

    [project.entry-points."bearcat.tasking"]
    spiral = "mypkg.uav:Spiral"

Every runtime takes it unchanged: ``bearcat simulate``, ``bearcat run``
(each peer process imports it), ``bearcat study`` and ``bearcat
experiment`` (locally or on Dask workers), fault plans and suites.
``bearcat plugins list`` shows what is registered and ``bearcat plugins
check SCENARIO`` imports and checks what a scenario names.

A plug-in is untrusted code in a peer that must not die: an exception, an
answer its protocol does not allow, or a live call past its budget is
logged in one sentence, counted, recorded as a ``plugin`` event that
``bearcat check`` judges, and that tick the agent stands still (or its
phone shows no advice, or its UAV keeps its last task).
"""

from bearcat.agents.ground_station.guidance.method import (
    GUIDANCE_METHODS,
    TRACKS,
    Advice,
    GuidanceMethod,
    GuidanceView,
)
from bearcat.agents.ground_station.tasking import NEEDS_SETS, TASKING, SearchView, TaskingPolicy, Uav
from bearcat.agents.guard import PluginFault
from bearcat.agents.human.behaviour import (
    BEHAVIOURS,
    COMMITS,
    TAKES_KEYS,
    TELLS,
    Behaviour,
    Commits,
    Situation,
    TakesKeys,
    Tells,
)
from bearcat.agents.human.phone import Screen, Sighting
from bearcat.agents.navigation import Navigator
from bearcat.agents.options import (
    Angle,
    Distance,
    Lag,
    Memory,
    NoOptions,
    Options,
    Period,
    Point,
    Route,
    Share,
)
from bearcat.agents.registry import Entry, PluginError, Registry
from bearcat.maps.geodesy import bearing
from bearcat.scenarios.game import GAMES, Game

REGISTRIES: tuple[Registry, ...] = (BEHAVIOURS, GUIDANCE_METHODS, TASKING, GAMES)
"""Every kind of plug-in, each its registry."""

__all__ = [
    "BEHAVIOURS",
    "COMMITS",
    "GAMES",
    "GUIDANCE_METHODS",
    "NEEDS_SETS",
    "REGISTRIES",
    "TAKES_KEYS",
    "TASKING",
    "TELLS",
    "TRACKS",
    "Advice",
    "Angle",
    "Behaviour",
    "Commits",
    "Distance",
    "Entry",
    "Game",
    "GuidanceMethod",
    "GuidanceView",
    "Lag",
    "Memory",
    "Navigator",
    "NoOptions",
    "Options",
    "Period",
    "PluginError",
    "PluginFault",
    "Point",
    "Registry",
    "Route",
    "Screen",
    "SearchView",
    "Share",
    "Sighting",
    "Situation",
    "TakesKeys",
    "TaskingPolicy",
    "Tells",
    "Uav",
    "bearing",
]
