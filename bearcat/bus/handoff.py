"""Work handed from Zenoh's threads to a peer's asyncio loop.

One wake-up a batch rather than one a sample: each ``call_soon_threadsafe``
writes a byte to the loop's self-pipe, and at hundreds of samples a second
a busy loop lets the pipe fill. A signal arriving then (the launcher's
SIGTERM) finds no room for its byte: Python prints a traceback and the
loop never runs the signal's handler.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections import deque
from collections.abc import Callable

log = logging.getLogger(__name__)


class Handoff:
    """``put(fn, *args)`` from any thread; the loop runs them in order."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self._queue: deque[tuple[Callable, tuple]] = deque()
        self._lock = threading.Lock()
        self._woken = False

    def put(self, fn: Callable, *args) -> None:
        with self._lock:
            self._queue.append((fn, args))
            if self._woken:
                return
            self._woken = True
        try:
            self.loop.call_soon_threadsafe(self._drain)
        except RuntimeError:  # the loop is closed: the peer is shutting down
            pass

    def _drain(self) -> None:
        with self._lock:
            batch, self._queue = self._queue, deque()
            self._woken = False
        for fn, args in batch:
            try:
                fn(*args)
            except Exception:
                log.exception("handling a sample failed; the peer goes on")
