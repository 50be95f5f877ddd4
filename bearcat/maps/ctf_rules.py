"""The rules and grids a capture-the-flag game on a map gets unless its
scenario says otherwise, shared by every entry point that builds a game
(scenarios, the command line)."""

from __future__ import annotations

import math

from bearcat.maps.model import Map
from bearcat.solvers.ctf.sets import Rules


def default_rules(
    game_map: Map,
    attacker_speed: float,
    defender_speed: float,
    *,
    capture_radius: float | None = None,
    capture_time: float | None = None,
    return_time: float | None = None,
) -> Rules:
    """Rules with the defaults every entry point shares: a capture radius of
    5% of the map's longer side, and stage times of 1.2 x that side over the
    slower speed (time to cross the map with room to manoeuvre)."""
    xmin, ymin, xmax, ymax = game_map.bounds
    side = max(xmax - xmin, ymax - ymin)
    horizon = 1.2 * side / min(attacker_speed, defender_speed)
    return Rules(
        attacker_speed=attacker_speed,
        defender_speed=defender_speed,
        capture_radius=0.05 * side if capture_radius is None else capture_radius,
        capture_time=capture_time or horizon,
        return_time=return_time or capture_time or horizon,
    )


def unresolved_capture(game_map: Map, grid: int, capture_radius: float) -> tuple[float, int] | None:
    """(cell, points needed) if a ``grid``-point grid over ``game_map`` is
    too coarse for ``capture_radius``, else None. The 4-D solver sees
    capture only where the radius spans a cell; below that the defender's
    winning set all but vanishes (on campus-250x200, a 5 m radius on 5.7 m
    cells left the attacker winning with the defender between it and home)."""
    xmin, ymin, xmax, ymax = game_map.bounds
    side = max(xmax - xmin, ymax - ymin)
    cell = side / (grid - 1)
    if capture_radius >= cell - 1e-9:
        return None
    return cell, math.ceil(side / capture_radius) + 1


PROVISIONAL_CELLS_PER_RADIUS = 1.2
"""Cells per capture radius of a derived provisional grid: at 1.2 the
fake-out's 25-point sets end its games as the 45-point sets do (README)."""
PROVISIONAL_SHARE = 0.6
"""A derived provisional grid above this share of the game's grid saves too little of the solve to be worth it."""


def provisional_grid(game_map: Map, grid: int, capture_radius: float, asked: int | None = None) -> int | None:
    """The points per axis of the sets a live run answers from while the
    ``grid``-point sets solve, or None to wait for those. ``asked`` is the
    scenario's choice (0: wait); unset, it is the coarsest grid with
    ``PROVISIONAL_CELLS_PER_RADIUS`` cells per capture radius, at least 21
    points, when that is well below ``grid``: the solve costs the fifth
    power of the points, so 25 points take a twentieth of 45's time."""
    if asked == 0:
        return None
    if asked is not None:
        return asked
    xmin, ymin, xmax, ymax = game_map.bounds
    side = max(xmax - xmin, ymax - ymin)
    derived = max(21, math.ceil(PROVISIONAL_CELLS_PER_RADIUS * side / capture_radius - 1e-9) + 1)
    return derived if derived <= PROVISIONAL_SHARE * grid else None
