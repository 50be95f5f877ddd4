"""The disk-full fault's disk: the run directory on a small tmpfs of its own.

A live run whose plan fills the disk mounts a tmpfs on its run directory
before it writes anything, so the fault can fill that disk (``fill``) and
no other. When the run is over its files are copied to the disk underneath
and the tmpfs goes: what the run recorded before the disk filled is kept,
and so is everything written after the fault. Mounting needs root.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from bearcat.scenarios.faults import FaultError

FILLER = ".filler"
CHUNK = 1 << 20


class SmallDisk:
    """``with SmallDisk(directory, size):`` the run directory on a tmpfs of ``size`` bytes."""

    def __init__(self, directory: Path, size: int) -> None:
        self.directory = Path(directory)
        self.size = int(size)
        self.mounted = False

    def __enter__(self) -> SmallDisk:
        self.directory.mkdir(parents=True, exist_ok=True)
        done = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={self.size},mode=0755", "tmpfs", str(self.directory)],
            capture_output=True,
            text=True,
        )
        if done.returncode != 0:
            said = (done.stderr or done.stdout).strip().splitlines()
            raise FaultError(
                f"the disk-full fault needs a tmpfs mounted on {self.directory}, and mount refused "
                f"({said[-1] if said else f'exit code {done.returncode}'}): run as root"
            )
        self.mounted = True
        return self

    def fill(self) -> None:
        """Write until the disk refuses."""
        with open(self.directory / FILLER, "wb", buffering=0) as filler:
            block = bytes(CHUNK)
            try:
                while True:
                    filler.write(block)
            except OSError:
                pass
            try:  # the last few blocks a page at a time, so not a byte is left
                while True:
                    filler.write(bytes(4096))
            except OSError:
                pass

    def __exit__(self, *_exc) -> None:
        if not self.mounted:
            return
        staging = Path(tempfile.mkdtemp(prefix=f".{self.directory.name}-", dir=self.directory.parent))
        try:
            shutil.copytree(self.directory, staging, dirs_exist_ok=True, ignore=shutil.ignore_patterns(FILLER))
            subprocess.run(["umount", str(self.directory)], check=False, capture_output=True)
            if os.path.ismount(self.directory):
                subprocess.run(["umount", "-l", str(self.directory)], check=False, capture_output=True)
            self.mounted = False
            shutil.copytree(staging, self.directory, dirs_exist_ok=True)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
