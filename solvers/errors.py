"""The one exception solvers raise for inputs a caller can get wrong, and
the checks of scalar arguments that raise it."""

import math


class InputError(ValueError):
    """A bad argument to a solver; the message names the culprit in one sentence."""


def positive(value, name: str) -> float:
    """``value`` as a float if it is a positive finite number, else an InputError naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (v > 0 and math.isfinite(v)):
        raise InputError(f"{name} must be a positive finite number, got {value!r}")
    return v


def non_negative(value, name: str) -> float:
    """``value`` as a float if it is a finite number >= 0, else an InputError naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (v >= 0 and math.isfinite(v)):
        raise InputError(f"{name} must be a finite number >= 0, got {value!r}")
    return v
