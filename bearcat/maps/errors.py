"""The one exception the map package raises for problems a user can cause."""


class MapError(ValueError):
    """A bad map name, map file or position; the message is one sentence naming the culprit."""
