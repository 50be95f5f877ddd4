"""Where bearcat keeps what it computes once and loads afterwards (solved
sets, calibrations, maneuvers), and how a file there is written so that a
reader never sees half of it. Shared by every cache, so none reaches into
another's module for them."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

CACHE_ENV = "BEARCAT_CACHE_DIR"


def cache_root() -> Path:
    """``$BEARCAT_CACHE_DIR``, else ``$XDG_CACHE_HOME/bearcat``, else ``~/.cache/bearcat``."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "bearcat"


def write_atomically(target: Path, write) -> None:
    """``write(file)`` into a temporary file beside ``target``, renamed onto
    it once complete: a reader sees the old file or the new, never half."""
    handle, temporary = tempfile.mkstemp(dir=target.parent, prefix=".partial-")
    try:
        with os.fdopen(handle, "wb") as f:
            write(f)
        os.replace(temporary, target)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
