"""The Rerun recording as a person sees it: pictures of a recorded run taken
by ``bearcat view RUN --screenshot PNG --at SECONDS`` (a real simulated run,
a real headless viewer), read back pixel by pixel. North is up, the flag
where the map puts it, the attacker's blue circle and the defender's red
triangle where each really was at that time, and nothing of the viewer's
own (its notices, its top bar) over the views."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread
from scipy import ndimage

from bearcat.agents.ground_station.rerun_recording import AREA, BLUE, RED, REGIONS
from bearcat.cli import live as cli_live
from bearcat.figures import screenshot
from bearcat.maps import load_map
from tests.support.scenario_files import write_scenario
from tests.support.system import missing_vulkan

pytestmark = pytest.mark.skipif(shutil.which("rerun") is None, reason="needs the Rerun viewer: pip install rerun-sdk")
renders = pytest.mark.skipif(missing_vulkan() is not None, reason=str(missing_vulkan()))
"""For the tests that take pictures; the viewer listens (and is checked) before it needs a driver."""

FIELD = load_map("field-50")  # 50 m x 50 m, the return strip y 45-50 m, the flag disk at (25, 15) m
TOLERANCE = 1.5  # m between a marker's centre in the picture and where its agent was


def bearcat(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bearcat", *map(str, args)], capture_output=True, text=True)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A fake-out on field-50, simulated and recorded by ``bearcat simulate --out``."""
    directory = tmp_path_factory.mktemp("viewer")
    done = bearcat("simulate", write_scenario(directory), "--out", directory / "out")
    assert done.returncode == 0, done.stderr
    (run,) = (directory / "out").iterdir()
    assert (run / "recording.rrd").exists()
    return run


def picture(run, at: float, png) -> np.ndarray:
    """``bearcat view RUN --screenshot PNG --at AT``, as RGB values 0-255."""
    done = bearcat("view", run, "--screenshot", png, "--at", at)
    if "ChildProcessError" in done.stderr:
        pytest.skip(f"the Rerun viewer cannot render here: {done.stderr.strip().splitlines()[-1]}")
    assert done.returncode == 0, done.stderr
    return np.round(imread(png)[..., :3] * 255).astype(int)


def tracks(run) -> dict[str, list[tuple[float, np.ndarray]]]:
    """Where each agent really was (game time, local metres), from the event log."""
    out: dict[str, list] = {}
    for line in (run / "events.jsonl").read_text().splitlines():
        e = json.loads(line)
        if e["event"] == "sent" and e["message"]["type"] == "truth":
            m = e["message"]
            out.setdefault(m["agent"], []).append((e["t"], np.array(FIELD.to_local(m["lat"], m["lon"]), float)))
    return out


def where(track, at: float) -> np.ndarray:
    """The last position of ``track`` at or before ``at``."""
    return [p for t, p in track if t <= at][-1]


class GroundView:
    """The ground station's view, the left half of the picture: where its map's area is drawn, and map metres
    to pixels if north is up and east right."""

    def __init__(self, image: np.ndarray) -> None:
        self.image = image[:, : image.shape[1] // 2]
        edges = _near(self.image, AREA, 10)
        rows = np.nonzero(edges.sum(axis=1) > 0.3 * self.image.shape[1])[0]
        columns = np.nonzero(edges.sum(axis=0) > 0.3 * self.image.shape[0])[0]
        assert len(rows) and len(columns), "no map area in the left half of the picture"
        self.top, self.bottom, self.left, self.right = rows.min(), rows.max(), columns.min(), columns.max()
        self.west, self.south, self.east, self.north = FIELD.bounds

    def pixel(self, x: float, y: float) -> np.ndarray:
        """(column, row) of map point (x, y), north up."""
        column = self.left + (x - self.west) / (self.east - self.west) * (self.right - self.left)
        row = self.top + (self.north - y) / (self.north - self.south) * (self.bottom - self.top)
        return np.array([column, row])

    def metres(self, column: float, row: float) -> np.ndarray:
        x = self.west + (column - self.left) / (self.right - self.left) * (self.east - self.west)
        y = self.north - (row - self.top) / (self.bottom - self.top) * (self.north - self.south)
        return np.array([x, y])

    def inside(self, mask: np.ndarray) -> np.ndarray:
        """``mask`` cut to the map area."""
        out = np.zeros_like(mask)
        out[self.top : self.bottom + 1, self.left : self.right + 1] = mask[
            self.top : self.bottom + 1, self.left : self.right + 1
        ]
        return out

    def marker(self, mask: np.ndarray) -> np.ndarray:
        """The centre, in map metres, of the largest blob of ``mask`` inside the area (a label's letters are
        smaller blobs)."""
        blobs, count = ndimage.label(self.inside(mask))
        assert count, "no marker of that colour on the map"
        largest = 1 + int(np.argmax(ndimage.sum_labels(np.ones_like(blobs), blobs, range(1, count + 1))))
        row, column = ndimage.center_of_mass(blobs == largest)
        return self.metres(column, row)


def _near(image: np.ndarray, colour, tolerance: int) -> np.ndarray:
    return (np.abs(image - np.asarray(colour)) <= tolerance).all(axis=2)


def _hue(image: np.ndarray, colour) -> np.ndarray:
    """Pixels of ``colour``'s hue, whatever the shading: each channel in the same proportion to the strongest."""
    strongest = image.max(axis=2, keepdims=True)
    ratio = image / np.maximum(strongest, 1)
    target = np.asarray(colour) / max(colour)
    return (np.abs(ratio - target) <= 0.12).all(axis=2) & (strongest[..., 0] > 100)


def _count_near(mask: np.ndarray, point, radius: float) -> int:
    column, row = np.round(point).astype(int)
    d = int(radius)
    return int(mask[row - d : row + d + 1, column - d : column + d + 1].sum())


@renders
def test_pictures_at_two_times_show_north_up_and_each_agent_where_it_was(run, tmp_path):
    track = tracks(run)
    attacker_track = track["attacker"]
    end = attacker_track[-1][0]
    early = 1.0
    # A later time when the attacker had moved well away.
    later = next(t for t, p in attacker_track if t < end - 0.5 and np.linalg.norm(p - where(attacker_track, early)) > 6)
    seen = {}
    for at in (early, later):
        image = picture(run, at, tmp_path / f"at-{at:g}.png")
        view = GroundView(image)
        # North up: the long green edge of the return strip (y = 45 m) is near the top of the map, none near
        # the bottom where it would be drawn with north down; the flag's ring (25, 15) sits low.
        green = view.inside(_hue(view.image, REGIONS))
        long_rows = np.nonzero(green.sum(axis=1) > 0.5 * (view.right - view.left))[0]
        assert len(long_rows) and np.abs(long_rows - view.pixel(25.0, 45.0)[1]).min() <= 4
        assert np.abs(long_rows - view.pixel(25.0, 5.0)[1]).min() > 20
        ring = 3.0 / (view.east - view.west) * (view.right - view.left)  # px, a bit over the flag's 2.5 m
        assert _count_near(green, view.pixel(25.0, 15.0), ring) > 20
        assert _count_near(green, view.pixel(25.0, 35.0), ring) == 0
        # The attacker a blue circle, the defender a red triangle, each where it really was.
        attacker = view.marker(_hue(view.image, BLUE))
        defender = view.marker(_hue(view.image, RED))
        assert np.linalg.norm(attacker - where(attacker_track, at)) < TOLERANCE
        assert np.linalg.norm(defender - where(track["defender"], at)) < TOLERANCE
        seen[at] = attacker
        # Nothing of the viewer's own over the views: no top bar (where its "Software rasterizer" badge sits),
        # no warning icon's orange, no notice's box.
        assert image[:30].max() < 60
        r, g, b = image[..., 0], image[..., 1], image[..., 2]
        assert not ((r > 200) & (g > 80) & (g < 180) & (b < 80)).any()
        boxes, count = ndimage.label(_near(image, (33, 33, 33), 0))
        assert count == 0 or ndimage.sum_labels(np.ones_like(boxes), boxes, range(1, count + 1)).max() < 5000
    assert np.linalg.norm(seen[later] - seen[early]) > 4.0


@renders
def test_a_time_after_the_end_or_without_a_picture_is_refused_in_one_sentence(run, tmp_path):
    done = bearcat("view", run, "--screenshot", tmp_path / "late.png", "--at", 1e6)
    if "ChildProcessError" in done.stderr:
        pytest.skip("the Rerun viewer cannot render here")
    assert done.returncode == 2 and "ends at" in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "late.png").exists()
    done = bearcat("view", run, "--at", 3)
    assert done.returncode == 2 and "--at needs --screenshot" in done.stderr
    done = bearcat("view", run, "--screenshot", tmp_path / "x.png", "--at", -1)
    assert done.returncode == 2 and "--at" in done.stderr


# ---------------------------------------------------------------- where the viewer listens


def listening(port: int) -> set[str]:
    """The addresses something on this host listens on at TCP ``port``, read from /proc/net/tcp and tcp6."""
    found = set()
    for table, family in (("/proc/net/tcp", socket.AF_INET), ("/proc/net/tcp6", socket.AF_INET6)):
        try:
            rows = Path(table).read_text().splitlines()[1:]
        except FileNotFoundError:
            continue
        for row in rows:
            local, state = row.split()[1], row.split()[3]
            address, at = local.split(":")
            if state == "0A" and int(at, 16) == port:  # 0A: LISTEN
                raw = bytes.fromhex(address)
                if sys.byteorder == "little":  # the kernel prints each 32-bit word in host order
                    raw = b"".join(raw[k : k + 4][::-1] for k in range(0, len(raw), 4))
                found.add(socket.inet_ntop(family, raw))
    return found


def heard(port: int, running, timeout: float = 60.0) -> set[str]:
    """Where ``port`` is listened on, once it is, while ``running()``; empty if it never was."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if found := listening(port):
            return found
        if not running():
            return listening(port)
        time.sleep(0.01)
    return set()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A recording of one point at one game time."""
    import rerun as rr

    path = tmp_path_factory.mktemp("tiny") / "recording.rrd"
    rec = rr.RecordingStream("bearcat-tiny")
    rec.save(path)
    rec.set_time(screenshot.TIMELINE, duration=1.0)
    rec.log("ground/point", rr.Points2D([[0.0, 0.0]]))
    rec.flush()
    return path


def test_the_headless_viewer_of_a_screenshot_listens_on_the_loopback_only(tiny, tmp_path, monkeypatch):
    """``bearcat view RUN --screenshot`` starts a viewer whose gRPC server
    (Rerun binds every interface unless told) answers this host only: asked
    for it on its command line, and seen in the kernel's table of listening
    sockets while it runs (it binds before it renders, so also where it
    cannot render)."""
    command = screenshot.viewer_command("rerun", tiny, 9876, (320, 240))
    assert command[command.index("--bind") + 1] == "127.0.0.1"
    port = free_port()
    monkeypatch.setattr(screenshot, "_free_port", lambda: port)
    taking = threading.Thread(
        target=lambda: _quietly(screenshot.screenshot, tiny, tmp_path / "shot.png", size=(320, 240)), daemon=True
    )
    taking.start()
    try:
        assert heard(port, taking.is_alive) == {"127.0.0.1"}
    finally:
        taking.join(timeout=90)


def test_the_viewer_bearcat_view_opens_listens_on_the_loopback_only(tiny, monkeypatch):
    """``bearcat view RUN`` opens a viewer, which starts a server with its
    window: on the loopback only. The socket is looked at with the same
    command run headless, which stays up where there is no display (a
    viewer without one exits some 50 ms after it binds, too soon to be
    seen every time)."""
    asked = []
    monkeypatch.setattr(subprocess, "call", lambda command: asked.append(command) or 0)
    port = free_port()
    assert cli_live._open_viewer(tiny, "--port", str(port)) == 0
    (command,) = asked
    assert command[command.index("--bind") + 1] == "127.0.0.1"
    viewer = subprocess.Popen(
        [*command, "--headless"],
        env=dict(os.environ, RUST_LOG="error", RERUN_APP_ONLY="true"),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        assert heard(port, lambda: viewer.poll() is None) == {"127.0.0.1"}
    finally:
        try:
            os.killpg(viewer.pid, 9)
        except ProcessLookupError:
            pass
        viewer.wait()


def _quietly(take, *args, **kwargs) -> None:
    """``take(...)``, whether or not this host's viewer can render (what is tested is where it listened)."""
    try:
        take(*args, **kwargs)
    except (ChildProcessError, TimeoutError):
        pass
