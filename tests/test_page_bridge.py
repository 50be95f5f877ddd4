"""``bearcat phone`` by hand, as on a second laptop: it fetches the game's
map from a ground station started by hand, serves the page over HTTPS to
whoever has the link's token, and joins the game, sealed with the player's
certificate, once the page has sent a fix. Stopped, it hands its log to
whoever runs the game (``--hand-in``), as a phone on another machine does
at the end of a run."""

import asyncio
import json
import signal
import subprocess
import sys
import time

import aiohttp

from bearcat.agents.ground_station.event_log import read_events
from bearcat.bus import keys
from bearcat.bus.zenoh_session import ZenohSession, config
from bearcat.runtime.credentials import add_to
from bearcat.runtime.hand_in import take_log
from bearcat.runtime.peer_commands import free_port
from bearcat.scenarios.schema import load_scenario
from tests.support.live_runs import wait_for
from tests.support.scenario_files import write_scenario

GAME = "test-game"


async def _visit(url: str, fix: dict) -> dict:
    """What a browser gets: the page, the map and a view on the socket; then it sends ``fix``."""
    base, token = url.split("?")
    found = {}
    async with aiohttp.ClientSession(connector=aiohttp.TCPConnector(ssl=False)) as http:
        async with http.get(url) as page:
            found["page"] = (page.status, "navigator.geolocation.watchPosition" in await page.text())
        async with http.get(base + "?token=wrong") as page:
            found["wrong token"] = page.status
        async with http.ws_connect(base + "ws?" + token) as ws:
            found["map"] = (await ws.receive_json())["map"]
            found["view"] = (await ws.receive_json())["view"]
            await ws.send_str(json.dumps({"type": "fix", **fix}))
            await ws.send_str("not json")
            # Views come as they change: the first to show both the fix and the drop, however late.
            while True:
                later = (await ws.receive_json())["view"]
                if later["fix"] is not None and later["dropped"]:
                    found["later"] = later
                    break
    return found


def test_bearcat_phone_by_hand_serves_its_page_and_joins_on_the_first_fix(tmp_path):
    path = write_scenario(tmp_path, time_limit=60.0, netem="ideal")
    scenario = load_scenario(path)
    certs = tmp_path / "certs"
    add_to(certs, scenario, phones=("attacker",))
    (tmp_path / "token").write_text("a-secret-of-the-attacker\n")
    out = tmp_path / "run"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    page_port = free_port()
    with ZenohSession("router", config(listen=[endpoint], mode="router")) as router:
        common = ("--connect", endpoint, "--certs", str(certs), "--out", str(out))
        gs = subprocess.Popen(
            [sys.executable, "-m", "bearcat", "peer", "ground-station", "--scenario", str(path), "--mode", "client"]
            + ["--judge", "fixes", *common]
        )
        phone = subprocess.Popen(
            [sys.executable, "-m", "bearcat", "phone", "--game", GAME, "--id", "attacker", *common]
            + ["--listen", f"127.0.0.1:{page_port}", "--token-file", str(tmp_path / "token"), "--hand-in"],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        try:
            first = phone.stdout.readline()
            assert first.startswith("open https://") and "a-secret-of-the-attacker" in first, first
            url = first.split()[1]
            assert wait_for(lambda: router.alive(keys.alive(GAME, "ground-station", "gs"), timeout=0.5), 120)
            token = keys.alive(GAME, "phone", "attacker")
            assert not router.alive(token, timeout=0.5)  # not in the game before its page sent a fix
            lat, lon = scenario.map.to_geodetic(25.0, 22.0)
            deadline = time.monotonic() + 60
            while True:  # the page is served once the scenario is fetched
                try:
                    found = asyncio.run(_visit(url, {"lat": lat, "lon": lon, "accuracy": 5.0, "age": 200.0}))
                    break
                except aiohttp.ClientConnectorError:
                    assert time.monotonic() < deadline and phone.poll() is None, "the page was never served"
                    time.sleep(0.2)
            # It joins on the fix its page sent, which its view showed already: at once, however loaded the host.
            assert wait_for(lambda: router.alive(token, timeout=0.5), 60), "the phone never joined"
            phone.send_signal(signal.SIGINT)
            laptop = tmp_path / "laptop"
            (laptop / "peers").mkdir(parents=True)
            # Its log is served from the moment its game has stopped, for a lease.
            seal = take_log(router, GAME, "attacker", laptop, lease=60.0)
            said, _ = phone.communicate(timeout=30)
        finally:
            for p in (phone, gs):
                if p.poll() is None:
                    p.kill()
                    p.wait()
    assert found["page"] == (200, True) and found["wrong token"] == 403
    assert found["map"]["bounds"] == [0.0, 0.0, 50.0, 50.0] and "home" in found["map"]["regions"]
    assert found["view"]["agent"] == "attacker" and found["view"]["fix"] is None
    assert found["later"]["fix"]["accuracy"] == 5.0 and found["later"]["dropped"] == 1
    assert phone.returncode == 0 and "peer attacker: interrupted" in said, said
    assert "and was handed to the launcher" in said, said
    kept = (out / "peers" / "attacker.jsonl").read_bytes()
    assert seal is not None and (laptop / "peers" / "attacker.jsonl").read_bytes() == kept
    assert seal.bytes == len(kept) and not seal.proven  # the router here holds no certificate
    received = [e for e in read_events(out / "peers" / "gs.jsonl") if e["event"] == "received"]
    assert any(e["key"] == keys.fix(GAME, "attacker") and e["sender"] == "attacker" for e in received)
    refused = [e for e in read_events(out / "peers" / "attacker.jsonl") if e["event"] == "refused"]
    assert [e["reason"] for e in refused] == ["the page sent something that is not a fix"]
