"""A person plays from a phone's browser: Chromium, driven by Playwright,
opens the page a live ``bearcat run --phone attacker`` serves, walks along
a path by emulated geolocation with a heading from an emulated orientation
sensor, and the game against a scripted defender ends with a verdict judged
on fixes.

Set ``BEARCAT_PHONE_SCREENSHOTS=DIR`` to keep the page's screenshots (the
README's come from there).
"""

import itertools
import json
import math
import os
import re
import shutil
import time
from importlib import resources

import pytest

from bearcat.agents.ground_station.event_log import read_events
from bearcat.agents.human.page_phone import PagePhone
from bearcat.bus import keys
from bearcat.bus.messages import Guidance, Report
from bearcat.maps import load_map
from bearcat.runtime.peer_commands import free_port
from bearcat.scenarios.schema import load_scenario
from tests.support.live_runs import start_launcher
from tests.support.scenario_files import write_scenario
from tests.support.system import CHROMIUM, missing_chromium

pytestmark = [
    pytest.mark.skipif(missing_chromium() is not None, reason=str(missing_chromium())),
    pytest.mark.xdist_group("browser-phone"),  # the module's fixtures are built once, in one xdist worker
]

HEADING = 330.0  # degrees the phone's top edge points to, through the orientation sensor
START = (25.0, 22.0)  # the attacker's start in the scenario
TOLD = """
from msgspec.structs import replace

from bearcat.plugins import GuidanceMethod


class Told(GuidanceMethod):
    needs = frozenset({"plain"})

    def advise(self, view):
        return replace(view.answers.plain(view), note="told by a method of one's own")
"""
"""The guidance method the game's phones are told by: the thesis's answer, with a line of its own."""
STEP = (-0.3, 0.35)  # metres per half second: up and to the left, towards home


def _path(k: int) -> tuple[float, float]:
    return (START[0] + STEP[0] * k, START[1] + STEP[1] * k)


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    base = tmp_path_factory.mktemp("browser")
    path = write_scenario(base, time_limit=20.0, netem="ideal")
    (base / "told.py").write_text(TOLD)
    path.write_text(path.read_text().replace('method = "none"', 'method = "told.py:Told"'))
    scenario = load_scenario(path)
    out, shots = base / "run", base / "shots"
    shots.mkdir()
    port = free_port()
    launcher = start_launcher(path, out, "--phone", "attacker", "--page", f"127.0.0.1:{port}")
    found = {"out": out, "scenario": scenario, "shots": shots}

    def geo(point):
        lat, lon = scenario.map.to_geodetic(*point)
        return {"latitude": lat, "longitude": lon, "accuracy": 4.0}

    try:
        said = []
        for line in launcher.stdout:
            said.append(line)
            if match := re.search(r"open (https://\S+) on it", line):
                url = match.group(1)
                break
        else:
            pytest.fail(f"the launcher printed no link: {''.join(said)}")
        from playwright import sync_api

        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
            context = browser.new_context(
                geolocation=geo(START),
                permissions=["geolocation", "accelerometer", "gyroscope", "magnetometer"],
                ignore_https_errors=True,  # the certificate the bridge made for this session
                viewport={"width": 390, "height": 760},
                device_scale_factor=2,
                is_mobile=True,
                has_touch=True,
            )
            found["without token"] = context.request.get(url.split("?")[0]).status
            found["wrong token"] = context.request.get(url.split("?")[0] + "?token=guess").status
            page = context.new_page()
            page.goto(url)
            sensors = context.new_cdp_session(page)
            sensors.send("Emulation.setSensorOverrideEnabled", {"enabled": True, "type": "absolute-orientation"})
            half = math.radians(-HEADING) / 2  # the sensor's yaw counts anticlockwise from north
            reading = {"quaternion": {"x": 0.0, "y": 0.0, "z": math.sin(half), "w": math.cos(half)}}
            sensors.send("Emulation.setSensorOverrideReadings", {"type": "absolute-orientation", "reading": reading})
            page.screenshot(path=shots / "1-start.png")
            page.click("#go")
            k = 0
            for k in range(120):
                context.set_geolocation(geo(_path(k)))
                time.sleep(0.5)
                if k == 12:
                    page.evaluate("state.socket.send(JSON.stringify({type: 'fix', lat: 123.0, lon: 0.0}))")
                if k == 16:
                    page.evaluate("state.socket.close()")  # the link drops, as when the screen sleeps
                if k == 20:
                    page.screenshot(path=shots / "2-playing.png")
                    found["playing"] = page.inner_text("body")
                if k == 22:
                    sensors.send("Page.setWebLifecycleState", {"state": "frozen"})  # the screen sleeps
                if k == 28:
                    sensors.send("Page.setWebLifecycleState", {"state": "active"})
                    found["woke"] = time.time()
                if page.inner_text("#phase") == "game over":
                    break
            found["steps"] = k
            time.sleep(1.0)
            page.screenshot(path=shots / "3-ended.png")
            found["ended"] = page.inner_text("body")
            browser.close()
        output, _ = launcher.communicate(timeout=120)
        found["output"] = "".join(said) + output
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()
    keep = os.environ.get("BEARCAT_PHONE_SCREENSHOTS")
    if keep:
        shutil.copytree(shots, keep, dirs_exist_ok=True)
    assert launcher.returncode == 0, found["output"]
    return found


def test_a_game_with_a_browser_phone_ends_with_a_verdict_judged_on_fixes(played):
    outcome = json.loads((played["out"] / "outcome.json").read_text())
    assert outcome["ended"] and outcome["winner"] in ("attacker", "defender"), outcome
    assert all(code == 0 for code in outcome["peers"].values()), outcome["peers"]
    states = [e["message"] for e in read_events(played["out"] / "events.jsonl") if e["event"] == "sent"]
    states = [m for m in states if m["type"] == "state"]
    assert states and all(m["judged_on"] == "fixes" for m in states)
    assert f"{outcome['winner'].upper()} WINS" in played["ended"] and outcome["reason"] in played["ended"]


def test_the_pages_fixes_follow_the_walk_with_the_phones_heading(played):
    game_map = played["scenario"].map
    fixes = [
        e["message"]
        for e in read_events(played["out"] / "events.jsonl")
        if e["event"] == "sent" and e["key"].endswith("/fix/attacker")
    ]
    assert len(fixes) >= 10
    walk = [_path(k) for k in range(played["steps"] + 1)]
    for fix in fixes:
        where = game_map.to_local(fix["lat"], fix["lon"])
        assert min(math.dist(where, p) for p in walk) < 0.5, where
        assert fix["accuracy"] == pytest.approx(4.0 / 2.4477, rel=1e-3)  # the browser's 95 % radius, as one sigma
    headings = [f["heading"] for f in fixes if f["heading"] is not None]
    assert headings and all(abs((h - HEADING + 180) % 360 - 180) < 2.0 for h in headings)
    seqs = [f["seq"] for f in fixes]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)


def test_the_screen_shows_the_opponent_the_guidance_and_a_bad_fix_dropped_and_counted(played):
    shown = played["playing"]
    assert "running" in shown and "online" in shown and "defender" in shown
    assert "told by a method of one's own" in shown
    assert "1 fixes dropped" in shown
    refused = [e for e in read_events(played["out"] / "peers" / "attacker.jsonl") if e["event"] == "refused"]
    assert len(refused) == 1 and "lat" in refused[0]["reason"]


def test_the_page_rejoins_after_its_link_dropped_and_after_it_slept(played):
    """The socket was closed mid-game: the page opened a new one (it is
    online four steps later) and its fixes went on; it was frozen for three
    seconds, as a sleeping screen freezes it, and its fixes went on after."""
    assert "online" in played["playing"]
    fixes = [
        e["t"]
        for e in read_events(played["out"] / "events.jsonl")
        if e["event"] == "sent" and e["key"].endswith("/fix/attacker")
    ]
    gaps = [b - a for a, b in itertools.pairwise(fixes)]
    awake = [t for t in fixes if t > played["woke"]]
    assert len(awake) >= 3
    assert max(b - a for a, b in itertools.pairwise([t for t in fixes if t < played["woke"] - 3.5])) < 3.0
    assert len(gaps) >= 10


def test_only_the_link_with_the_players_token_opens_the_page(played):
    assert played["without token"] == 403 and played["wrong token"] == 403


def test_three_screenshots_of_the_game(played):
    shots = sorted(played["shots"].glob("*.png"))
    assert [s.name for s in shots] == ["1-start.png", "2-playing.png", "3-ended.png"]
    images = [s.read_bytes() for s in shots]
    assert all(i.startswith(b"\x89PNG") and len(i) > 5000 for i in images)
    assert len(set(images)) == 3


# ---------------------------------------------------------------- the page alone, fed a view


CENTRE, MAJOR, MINOR, BEARING = (25.0, 30.0), 14.0, 6.0, 30.0  # the defender's predicted position and ellipse


def _pixels_around(page, points: dict, reach: int = 2) -> dict:
    """The RGB of the canvas's pixels within ``reach`` of each map point (metres),
    placed as the page places them: the field fitted to the canvas, 10 px of
    margin, north up."""
    script = """([bounds, points, reach]) => {
      const canvas = document.getElementById("map"), g = canvas.getContext("2d");
      const ratio = canvas.width / canvas.clientWidth, w = canvas.clientWidth, h = canvas.clientHeight;
      const [x0, y0, x1, y1] = bounds;
      const scale = Math.min((w - 20) / (x1 - x0), (h - 20) / (y1 - y0));
      const ox = (w - scale * (x1 - x0)) / 2, oy = (h - scale * (y1 - y0)) / 2;
      const out = {};
      for (const [name, [x, y]] of Object.entries(points)) {
        const px = Math.round((ox + (x - x0) * scale) * ratio), py = Math.round((h - oy - (y - y0) * scale) * ratio);
        const d = g.getImageData(px - reach, py - reach, 2 * reach + 1, 2 * reach + 1).data;
        out[name] = [];
        for (let i = 0; i < d.length; i += 4) out[name].push([d[i], d[i + 1], d[i + 2]]);
      }
      return out;
    }"""
    return page.evaluate(script, [[0.0, 0.0, 50.0, 50.0], points, reach])


def _bright(pixels) -> bool:
    """Whether any pixel is white or grey (the ellipse's and the disks' strokes), not a colour or the ground."""
    return any(min(p) >= 120 for p in pixels)


def test_the_page_draws_the_predicted_position_inside_its_ellipse_turned_by_its_bearing():
    """A view with a calibrated report, as the bridge sends it: the page
    draws the defender's predicted position joined to its fix, and the
    ellipse passes through the ends of both axes, turned by the bearing
    (clockwise from north, with the canvas's y pointing down), not through
    the points a swapped axis or a mirrored turn would give; the report
    without a prediction keeps its disk, the one with it has none."""
    from playwright import sync_api

    phone = PagePhone("g", "attacker", load_map("field-50"))
    m = phone.map
    fix_d, fix_a = (10.0, 42.0), (40.0, 10.0)
    (d_lat, d_lon), (a_lat, a_lon), (p_lat, p_lon) = (m.to_geodetic(*p) for p in (fix_d, fix_a, CENTRE))
    reports = [
        Report("defender", 9.0, d_lat, d_lon, radius=8.0, predicted=(p_lon, p_lat), ellipse=(MAJOR, MINOR, BEARING)),
        Report("attacker", 9.5, a_lat, a_lon, radius=5.0),
    ]
    phone.handle(
        keys.guidance("g", "attacker"), Guidance(agent="attacker", seq=1, t=10.0, game="ctf", reports=reports), 10.0
    )
    messages = [{"type": "map", "map": phone.map_view()}, {"type": "view", "view": phone.view(10.0)}]

    b = math.radians(BEARING)
    along, across = (math.sin(b), math.cos(b)), (math.cos(b), -math.sin(b))  # east, north

    def off(axis, metres):
        return (CENTRE[0] + metres * axis[0], CENTRE[1] + metres * axis[1])

    points = {
        "major ahead": off(along, MAJOR),
        "major behind": off(along, -MAJOR),
        "minor right": off(across, MINOR),
        "minor left": off(across, -MINOR),
        "minor along the major axis": off(along, MINOR),
        "major along the minor axis": off(across, MAJOR),
        "major mirrored": (CENTRE[0] - MAJOR * along[0], CENTRE[1] + MAJOR * along[1]),
        "predicted": CENTRE,
        "between fix and prediction": ((fix_d[0] + CENTRE[0]) / 2, (fix_d[1] + CENTRE[1]) / 2),
        "defender's disk": (fix_d[0], fix_d[1] - 8.0),
        "attacker's disk": (fix_a[0], fix_a[1] - 5.0),
    }
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 390, "height": 760}, device_scale_factor=2)
            index = resources.files("bearcat.agents.human").joinpath("page/index.html").read_text()
            page.route("https://phone.test/**", lambda route: route.fulfill(body=index, content_type="text/html"))
            page.route_web_socket(
                re.compile(r"wss://phone\.test/ws.*"), lambda ws: [ws.send(json.dumps(message)) for message in messages]
            )
            page.goto("https://phone.test/?token=t")
            page.wait_for_function("state.map !== null && state.view !== null")
            page.evaluate("draw()")
            seen = _pixels_around(page, points)
        finally:
            browser.close()
    drawn = {name for name, pixels in seen.items() if _bright(pixels)}
    assert drawn == {"major ahead", "major behind", "minor right", "minor left", "attacker's disk"}, drawn
    magenta = {name for name, pixels in seen.items() if any(r > 200 and g < 60 and bl > 200 for r, g, bl in pixels)}
    assert {"predicted", "between fix and prediction"} <= magenta, magenta
