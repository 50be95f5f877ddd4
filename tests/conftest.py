"""Session-wide test settings.

Every test session solves games into its own cache directory, so the suite
never writes 4-D value functions into the user's ``~/.cache/bearcat`` and
never reads a set some earlier version of the code stored there.
"""

import pytest


@pytest.fixture(autouse=True, scope="session")
def private_cache_dir(tmp_path_factory):
    """``$BEARCAT_CACHE_DIR`` for the whole session, inherited by the peers tests start."""
    path = tmp_path_factory.mktemp("bearcat-cache")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("BEARCAT_CACHE_DIR", str(path))
        yield path
