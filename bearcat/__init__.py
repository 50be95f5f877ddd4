"""bearcat: field simulator for reachability-guided adversarial games.

The subpackages (``bearcat.solvers``, ``bearcat.bus``, ...) live in folders at
the repository root and are installed under this package by setuptools'
``package-dir`` mapping. Python started inside a checkout finds this folder
before the installed package; the finder below then maps the same names to
the checkout's folders, so every subpackage comes from the same checkout as
this module instead of failing to import.
"""

import sys
from importlib.machinery import PathFinder
from pathlib import Path

__version__ = "0.1.0"

SUBPACKAGES = ("agents", "bus", "maps", "netem", "scenarios", "solvers")
"""The root folders that install as ``bearcat.<name>`` (pyproject.toml's package-dir)."""


class _CheckoutSubpackages:
    """Finds ``bearcat.<name>`` in the checkout's ``<name>/`` folder, as package-dir maps it."""

    def __init__(self, root: Path) -> None:
        self.root = str(root)

    def find_spec(self, fullname, path=None, target=None):
        parent, _, name = fullname.rpartition(".")
        if parent != __name__ or name not in SUBPACKAGES:
            return None
        return PathFinder.find_spec(fullname, [self.root])


_checkout = Path(__file__).resolve().parent.parent
if (_checkout / "pyproject.toml").is_file() and not (Path(__file__).parent / "bus").is_dir():
    sys.meta_path.insert(0, _CheckoutSubpackages(_checkout))
