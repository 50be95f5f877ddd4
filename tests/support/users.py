"""What a user does from a folder of their own: run the ``bearcat``
command, and install the example package of plug-ins."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BEARCAT = str(Path(sys.executable).with_name("bearcat"))  # the console script a user types


def bearcat(*words, cwd: Path, env: dict | None = None, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [BEARCAT, *map(str, words)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=os.environ | (env or {}) | {"PYTHONUNBUFFERED": "1"},
    )


def install_tactics(target: Path) -> Path:
    """The example distribution, installed by pip into ``target`` (for
    PYTHONPATH), not into the environment."""
    done = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--no-index", "-q"]
        + ["--target", str(target), str(ROOT / "examples" / "bearcat-tactics")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    return target
