"""Where a command's output goes, so that ``--json`` pipes into other programs.

One rule for every command: with ``--json`` and no file (or ``--json -``),
stdout carries the JSON and nothing else, and every line meant for a person
(summaries, tables, "wrote x.png") goes to stderr beside the progress bars.
With ``--json FILE`` the JSON goes to the file and stdout keeps the lines
for a person, as it does without ``--json``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from bearcat.cli.writing import writing


class Output:
    """A command's two streams. ``json_to`` is the ``--json`` option's value:
    None or False (no JSON), True or ``-`` (stdout), or a file."""

    def __init__(self, json_to: Path | str | bool | None) -> None:
        self.json_on_stdout = json_to is True or (isinstance(json_to, (str, Path)) and str(json_to) == "-")
        self.json_file = Path(json_to) if isinstance(json_to, (str, Path)) and not self.json_on_stdout else None

    @property
    def human(self):
        """The stream for a person: stderr when stdout carries JSON."""
        return sys.stderr if self.json_on_stdout else sys.stdout

    @property
    def wants_json(self) -> bool:
        return self.json_on_stdout or self.json_file is not None

    def say(self, text: str) -> None:
        print(text, file=self.human, flush=True)

    def json(self, data, *, indent: int | None = 2) -> None:
        """Write ``data`` where ``--json`` asked, if it was; ``indent=None``
        gives one line, for a stream of objects (JSON Lines)."""
        text = json.dumps(data, indent=indent)
        if self.json_on_stdout:
            print(text, flush=True)
        elif self.json_file is not None:
            with writing(self.json_file, "JSON file"):
                self.json_file.write_text(text + "\n")
            self.say(f"wrote {self.json_file}")

    def figure(self, figure, path: Path, **savefig) -> None:
        """Save a matplotlib figure where the user asked and say so."""
        with writing(path, "figure"):
            figure.savefig(path, **savefig)
        self.say(f"wrote {path}")


def add_json_option(parser, what: str) -> None:
    """``--json [FILE]`` for a command without positional arguments (one
    would be taken for the FILE)."""
    parser.add_argument(
        "--json",
        type=Path,
        nargs="?",
        const=Path("-"),
        metavar="FILE",
        help=f"write {what} as JSON to FILE, or without FILE to stdout alone (the text for a person then goes to "
        "stderr)",
    )
