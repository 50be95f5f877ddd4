"""The one exception solvers raise for inputs a caller can get wrong."""


class InputError(ValueError):
    """A bad argument to a solver; the message names the culprit in one sentence."""
