"""Which processor a level-set solve runs on: ``"cpu"`` (numba's CPU
kernels on every core numba uses), ``"cuda"`` (the numba-cuda kernels of
``solvers.levelset.cuda`` on a CUDA GPU) or ``"auto"`` (a GPU when numba-cuda
finds one, else the CPU).

numba-cuda is an optional dependency (``pip install 'bearcat[cuda]'``): it
is imported only to look for a GPU, never by a CPU solve. Under numba's
CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, set before numba-cuda is first
imported) ``"cuda"`` runs the same kernels on the CPU, one simulated thread
at a time, which is how the kernels are tested without a GPU; ``"auto"``
never picks the simulator, which is no GPU.
"""

from __future__ import annotations

import importlib.util
import logging
import os
from dataclasses import dataclass

from bearcat.solvers.errors import InputError

__all__ = ["DEVICES", "Device", "choose_device", "find_gpu"]

log = logging.getLogger(__name__)

DEVICES = ("auto", "cpu", "cuda")
"""The devices a solve may be asked for."""

CUDA_EXTRA = "pip install 'bearcat[cuda]'"


@dataclass(frozen=True)
class Gpu:
    """A CUDA device numba-cuda found: its name, and whether it is numba's simulator."""

    name: str
    simulated: bool = False


@dataclass(frozen=True)
class Device:
    """The device a solve runs on: ``kind`` ``"cpu"`` or ``"cuda"``, the GPU
    if CUDA, and why ``"auto"`` chose it."""

    kind: str
    gpu: Gpu | None = None
    reason: str = ""

    def __str__(self) -> str:
        if self.gpu is None:
            import numba

            return f"the CPU with {numba.get_num_threads()} threads"
        return self.gpu.name if self.gpu.simulated else f"the GPU {self.gpu.name}"


def find_gpu() -> Gpu | str:
    """The CUDA GPU numba-cuda would run on (device 0), or a clause saying why
    there is none. Looked for once per process: a process forked from one
    that used the GPU looks again, and CUDA, which does not survive a fork,
    then says so, and ``"auto"`` takes the CPU there."""
    pid = os.getpid()
    if pid not in _found:
        _found[pid] = _look_for_gpu()
    return _found[pid]


_found: dict[int, Gpu | str] = {}


def _look_for_gpu() -> Gpu | str:
    if importlib.util.find_spec("numba_cuda") is None:
        return f"numba-cuda is not installed ({CUDA_EXTRA})"
    try:
        from numba import cuda
        from numba.core import config

        if getattr(config, "ENABLE_CUDASIM", 0):
            return Gpu("numba's CUDA simulator", simulated=True)
        if not cuda.is_available():
            return "numba-cuda finds no CUDA GPU or driver"
        name = cuda.get_current_device().name
    except Exception as exc:  # a broken driver or toolkit raises many kinds of errors
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return f"numba-cuda could not reach a GPU ({first})"
    return Gpu(name.decode() if isinstance(name, bytes) else str(name))


def choose_device(device: str, *, unsupported: str | None = None) -> Device:
    """The device to solve on for a request of ``device`` (one of
    ``DEVICES``). ``unsupported`` says why this problem cannot run on a GPU
    (None if it can): ``"auto"`` then takes the CPU, ``"cuda"`` is refused.
    ``"cuda"`` without a GPU is an InputError, in one sentence."""
    if device not in DEVICES:
        raise InputError(f"device must be one of {', '.join(DEVICES)}, got {device!r}")
    if device == "cpu":
        return Device("cpu")
    if unsupported is not None:
        if device == "cuda":
            raise InputError(f"device 'cuda' cannot solve this problem: {unsupported}; use device 'cpu' or 'auto'")
        return _chosen(Device("cpu", reason=unsupported))
    found = find_gpu()
    if device == "cuda":
        if isinstance(found, str):
            raise InputError(f"device 'cuda' needs a CUDA GPU, but {found}; use device 'cpu' or 'auto'")
        return Device("cuda", found)
    if isinstance(found, str):
        return _chosen(Device("cpu", reason=found))
    if found.simulated:
        return _chosen(Device("cpu", reason="the CUDA simulator is no GPU"))
    return _chosen(Device("cuda", found, reason="numba-cuda found it"))


def _chosen(device: Device) -> Device:
    log.info("device auto: solving on %s: %s", device, device.reason)
    return device
