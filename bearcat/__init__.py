"""bearcat: field simulator for reachability-guided adversarial games.

The subpackages (``bearcat.solvers``, ``bearcat.bus``, ...) live in folders at
the repository root and are installed under this package by setuptools'
``package-dir`` mapping. Python started inside a checkout finds this folder
before the installed package, so the checkout's root joins the search path
here: the subpackages then come from the same checkout as this module instead
of failing to import.
"""

from pathlib import Path

__version__ = "0.1.0"

_checkout = Path(__file__).resolve().parent.parent
if (_checkout / "pyproject.toml").is_file() and not (Path(__file__).parent / "bus").is_dir():
    __path__.append(str(_checkout))
