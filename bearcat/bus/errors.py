"""The one exception the bus raises for problems a user can cause."""


class BusError(ValueError):
    """A bad key, name, endpoint or message; the text is one sentence naming the culprit."""
