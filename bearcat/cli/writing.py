"""A directory or file the user named that refuses a write, as one sentence.

The commands write where the user points them (``--out``, ``--json FILE``,
``--plot``, ``$BEARCAT_CACHE_DIR``). When that place is full, read-only or
not a directory, the OS's error is the user's to fix, and ``writing`` turns
it into a ``WriteError`` naming the place and the reason. Any other
``OSError`` in the same block keeps its traceback, since it points at a bug:
the error must name the place (or a file in it, or a parent of it), or carry
no name at all and be one of the disk's refusals, which writes through an
open file raise without a name, or a short write a library reports without
the OS's error number (numpy's ``tofile`` does). So a guard encloses code
that writes to its place only, and not to another that could fill up too.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

#: What a full, read-only or over-quota disk raises on a write through an open file.
DISK_REFUSALS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS})


class WriteError(Exception):
    """The place the user named refuses a write; the text names it and says why."""


@contextmanager
def writing(place: Path | str, what: str) -> Iterator[None]:
    """Raise ``WriteError("cannot write {what} {place}: {reason}")`` for an
    ``OSError`` inside the block that concerns ``place``."""
    place = Path(place)
    try:
        yield
    except OSError as exc:
        if not _concerns(exc, place):
            raise
        raise WriteError(f"cannot write {what} {place}: {_reason(exc, place)}") from None


def _concerns(exc: OSError, place: Path) -> bool:
    if exc.filename is None:
        return exc.errno is None or exc.errno in DISK_REFUSALS
    named = Path(os.fsdecode(exc.filename)).absolute()
    place = place.absolute()
    return named == place or place in named.parents or named in place.parents


def _reason(exc: OSError, place: Path) -> str:
    """The OS's words, except that a file standing where a directory must be is named."""
    if exc.errno in (errno.ENOTDIR, errno.EEXIST):
        for step in (place, *place.parents):
            if step.exists():
                if not step.is_dir():
                    return f"{step} is a file, not a directory"
                break
    if exc.errno is None:
        return f"a write stopped short ({exc}); is its disk full?"
    return exc.strerror or str(exc)


def make_directory(path: Path, what: str) -> None:
    """Create ``path`` and its parents before any work, so a place that
    cannot hold them is named at once rather than after a solve."""
    with writing(path, what):
        path.mkdir(parents=True, exist_ok=True)
