"""Session-wide test settings.

Every test session solves games into its own cache directory, so the suite
never writes 4-D value functions into the user's ``~/.cache/bearcat`` and
never reads a set some earlier version of the code stored there. The
workers of one parallel session (pytest-xdist) share it: a game one of them
solved, the others load (``ctf_cache`` makes them take turns).
"""

import compileall
import os
import sys
from pathlib import Path

import pytest

import bearcat


def pytest_configure(config):
    """Compile the package's bytecode once, before any worker starts. The
    suite starts hundreds of Python processes (each peer of each live game,
    each command a test runs); where bytecode is not written
    (``PYTHONDONTWRITEBYTECODE``, as in many containers), each would compile
    the package's source again, a fifth of a second of CPU apiece."""
    if sys.dont_write_bytecode and not hasattr(config, "workerinput"):
        compileall.compile_dir(Path(bearcat.__file__).parent, quiet=1)


@pytest.fixture(autouse=True, scope="session")
def private_cache_dir(tmp_path_factory):
    """``$BEARCAT_CACHE_DIR`` for the whole session, inherited by the peers tests start."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        path = tmp_path_factory.getbasetemp().parent / "bearcat-cache"
        path.mkdir(exist_ok=True)
    else:
        path = tmp_path_factory.mktemp("bearcat-cache")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("BEARCAT_CACHE_DIR", str(path))
        yield path


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """Refuse a parallel session whose groups would silently run apart.

    The tests of one ``xdist_group`` share a module's game, or the host's
    links, and must run in one worker; pytest-xdist's ``--dist loadgroup``
    marks them by suffixing their node ids in each worker, which some
    pairings of pytest and pytest-xdist undo (pytest-dev/pytest-xdist#1386).
    """
    if not getattr(config.option, "loadgroup", False):
        return
    lost = [item.nodeid for item in items if item.get_closest_marker("xdist_group") and "@" not in item.nodeid]
    if lost:
        raise pytest.UsageError(
            f"--dist loadgroup does not group {lost[0]} (and {len(lost) - 1} more) with this pytest "
            f"{pytest.__version__} and pytest-xdist: install the versions pyproject.toml's test extra names"
        )
