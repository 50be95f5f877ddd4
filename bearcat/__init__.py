"""bearcat: field simulator for reachability-guided adversarial games.

The subpackages are layered, each importing only those below it:
``cli`` over ``studies``, ``suites`` and ``figures``, over ``runtime``, over
``scenarios``, over ``agents``, over ``bus``, ``netem``, ``solvers`` and
``maps``.
"""

__version__ = "0.1.0"
