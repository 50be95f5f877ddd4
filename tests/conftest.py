"""Session-wide test settings.

Every test session solves games into its own cache directory, so the suite
never writes 4-D value functions into the user's ``~/.cache/bearcat`` and
never reads a set some earlier version of the code stored there. The
workers of one parallel session (pytest-xdist) share it: a game one of them
solved, the others load (``ctf_cache`` makes them take turns).
"""

import os

import pytest


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
