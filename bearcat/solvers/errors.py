"""The one exception solvers raise for inputs a caller can get wrong, the
checks of scalar arguments that raise it, and how its messages write a point."""

import math

import numpy as np


class InputError(ValueError):
    """A bad argument to a solver; the message names the culprit in one sentence."""


def positive(value, name: str) -> float:
    """``value`` as a float if it is a positive finite number, else an InputError naming ``name``."""
    v = _number(value)
    if not (v > 0 and math.isfinite(v)):
        raise InputError(f"{name} must be a positive finite number, got {value!r}")
    return v


def non_negative(value, name: str, *, finite: bool = True) -> float:
    """``value`` as a float if it is a number >= 0, finite unless ``finite``
    is False (a range without limit), else an InputError naming ``name``."""
    v = _number(value)
    if not (v >= 0 and (math.isfinite(v) or not finite)):
        raise InputError(f"{name} must be a {'finite ' if finite else ''}number >= 0, got {value!r}")
    return v


def fraction(value, name: str) -> float:
    """``value`` as a float if it lies in ``(0, 1]``, else an InputError naming ``name``."""
    v = _number(value)
    if not 0 < v <= 1:
        raise InputError(f"{name} must be a number in (0, 1], got {value!r}")
    return v


def format_point(point) -> str:
    """``(x, y, ...)`` as messages write a point."""
    return "(" + ", ".join(f"{float(c):g}" for c in np.ravel(point)) + ")"


def _number(value) -> float:
    """``value`` as a float; NaN, which every check refuses, for what is not a
    number (text included, though ``float`` would read it)."""
    if isinstance(value, (str, bytes)):
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan
