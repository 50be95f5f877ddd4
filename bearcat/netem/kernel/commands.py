"""The system commands kernel mode runs, each failure one sentence naming
the command and what it said."""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import time


class KernelError(RuntimeError):
    """A kernel network could not be built or used; the text says which step failed and why."""


def run(*argv: str) -> str:
    """Run ``argv``; its standard output, or a ``KernelError`` quoting the command and its error."""
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=30)
    except FileNotFoundError:
        raise KernelError(f"{argv[0]} is not installed") from None
    except subprocess.TimeoutExpired:
        raise KernelError(f"'{' '.join(argv)}' did not finish within 30 s") from None
    if done.returncode != 0:
        said = (done.stderr or done.stdout).strip().splitlines()
        raise KernelError(f"'{' '.join(argv)}' failed: {said[-1] if said else f'exit code {done.returncode}'}")
    return done.stdout


def inside(pid: int, *argv: str) -> str:
    """Run ``argv`` in the network namespace of process ``pid``."""
    return run("nsenter", "-t", str(pid), "-n", *argv)


def namespace_of(pid: int | str) -> int:
    """The inode that names the network namespace of process ``pid`` ("self" for this one)."""
    return os.stat(f"/proc/{pid}/ns/net").st_ino


def await_namespace(pid: int, name: str, timeout: float) -> None:
    """Wait until process ``pid`` (``unshare --net``) is in a network
    namespace of its own; a ``KernelError`` naming ``name`` if it never is."""
    own = namespace_of("self")
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            if namespace_of(pid) != own:
                return
        except FileNotFoundError:
            break
        time.sleep(0.005)
    raise KernelError(f"{name} never got a network namespace of its own (unshare --net failed?)")


def die_with_parent(sig: int = signal.SIGKILL) -> None:
    """In a child before it runs its program: send it ``sig`` when its parent
    dies. The signal outlives ``exec``, so a program started this way dies
    with the launcher however the launcher ends; a peer, sent SIGTERM, says
    so in its log on its way out."""
    ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, sig)


def die_saying_so() -> None:
    """``die_with_parent`` by SIGTERM, which a peer and a vehicle end on cleanly, saying why."""
    die_with_parent(signal.SIGTERM)


_PR_SET_PDEATHSIG = 1
