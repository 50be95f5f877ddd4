"""A picture of a run's Rerun recording at a chosen game time, taken by a
headless Rerun viewer.

The viewer runs as a child process on a free port of the loopback (its
server answers this machine only: Rerun binds every interface unless told
otherwise) and is driven through
``rerun.experimental.ViewerClient``: wait for the recording, hide the
viewer's own panels, pause the time line at the chosen time and save what
the views show. Its log is cut to errors, since the viewer shows its log as
notices over the views (a software rasteriser, as on machines without a
GPU, is always worth a warning).
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path

TIMELINE = "game_time"
PANELS = ("/top_panel", "/blueprint_panel", "/selection_panel")
SETTLE_FRAMES = 20  # pictures at most until two agree
LOOPBACK = "127.0.0.1"  # the only address the viewer's server listens on
STARTUP = 60.0  # s for the viewer to start and load the recording (a software rasteriser on a loaded host is slow)


class ScreenshotError(ValueError):
    """A time asked for that the recording does not reach; the text names both."""


def screenshot(rrd: Path, png: Path, *, at: float | None = None, size: tuple[int, int] = (1600, 900)) -> float:
    """Save the views of recording ``rrd`` at game time ``at`` (seconds from
    the start; None: the end) to ``png``; the game time shown."""
    viewer = shutil.which("rerun")
    if viewer is None:
        raise FileNotFoundError("the Rerun viewer is not installed: pip install rerun-sdk")
    port = _free_port()
    command = viewer_command(viewer, rrd, port, size)
    environment = dict(os.environ, RUST_LOG="error", RERUN_APP_ONLY="true")
    with tempfile.TemporaryFile() as errors:
        # Its own session, so stopping it stops the viewer binary the ``rerun`` launcher starts too.
        process = subprocess.Popen(
            command, env=environment, stdin=subprocess.DEVNULL, stdout=errors, stderr=errors, start_new_session=True
        )
        try:
            client, end = _wait_for_recording(port, process, errors, rrd)
            shown = end if at is None else at
            if shown > end:
                raise ScreenshotError(f"--at {at:g}: the recording of {rrd.parent} ends at {end:.1f} s")
            blueprint = client.get_blueprint().blueprint
            for panel in PANELS:
                blueprint[panel] = {"PanelBlueprint": {"state": "Hidden"}}
            blueprint.setdefault("/time_panel", {}).setdefault("TimePanelBlueprint", {})["state"] = "Hidden"
            client.set_blueprint(blueprint, of="recording")
            client.set_time(TIMELINE, duration=shown, play_state="paused")
            png.write_bytes(_settled_picture(client))
            return shown
        finally:
            _stop(process)


def viewer_command(viewer: str, rrd: Path, port: int, size: tuple[int, int]) -> list[str]:
    """The command line of a headless viewer of ``rrd`` whose server listens on ``port`` of the loopback only."""
    window = f"{size[0]}x{size[1]}"
    return [viewer, str(rrd), "--headless", "--bind", LOOPBACK, "--port", str(port), "--window-size", window]


def _wait_for_recording(port: int, process: subprocess.Popen, errors, rrd: Path):
    """Wait until the viewer shows the recording; a client of the viewer, and
    where the recording's time line ends (s)."""
    from rerun.experimental import ViewerClient

    deadline = time.monotonic() + STARTUP
    while time.monotonic() < deadline:
        if process.poll() is not None:
            errors.seek(0)
            lines = [line for line in errors.read().decode(errors="replace").splitlines() if line.strip()]
            why = next((line.strip() for line in lines if "panicked" in line), lines[-1].strip() if lines else "")
            raise ChildProcessError(
                f"the Rerun viewer exited with code {process.returncode} before it could render {rrd} "
                f"(it needs a Vulkan driver, such as Mesa's for a CPU): {why}"
            )
        try:
            client = ViewerClient.connect(f"rerun+http://{LOOPBACK}:{port}/proxy")
            state = client.get_state()
        except ConnectionError:  # not listening yet
            time.sleep(0.1)
            continue
        recording = next((r for r in state.recordings if r.store_id == state.active_recording), None)
        timeline = None if recording is None else next((t for t in recording.timelines if t.name == TIMELINE), None)
        if timeline is not None and not state.loading:
            return client, (timeline.end or 0) / 1e9
        time.sleep(0.1)
    raise TimeoutError(f"the Rerun viewer did not show {rrd} within {STARTUP:g} s")


def _settled_picture(client) -> bytes:
    """The picture once two in a row agree: the viewer fetches a recording's
    chunks as its views first ask for them, so the first frames at a new
    time may lack some of what was there."""
    previous = None
    for _ in range(SETTLE_FRAMES):
        picture = client.take_screenshot()
        if picture == previous:
            break
        previous = picture
    return picture


def _stop(process: subprocess.Popen) -> None:
    try:
        os.killpg(process.pid, signal.SIGTERM)
        process.wait(timeout=10)
    except ProcessLookupError:
        pass
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind((LOOPBACK, 0))
        return s.getsockname()[1]
