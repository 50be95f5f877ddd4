"""Peers on more than one computer: a game whose launcher runs on one
machine and whose walker and UAV run on another, over a guarded bus.

Network namespaces stand in for the computers (``support.machines``): the
ground station's laptop, a field computer joined to it by a veth pair, and
two strangers. The laptop runs ``bearcat run --secure --listen
tls/LAPTOP:7447 --joins attacker --joins q1`` with certificates from
``bearcat certs init --host LAPTOP``; the field computer runs the commands
the launcher printed (the attacker's walker, and the UAV peer beside a
vehicle emulator), which fetch the scenario from the ground station. A
stranger with no certificate and one with another authority's try to
connect while the game waits; mid-game, one of them with the attacker's
certificate reads what it can, and the UAV's peer is killed. The game
ends with a verdict, ``bearcat check`` holds, and nothing is left. The
browser test opens a phone's page from the other machine.

They need root for the namespaces and skip, saying why, without it.
"""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bearcat.agents.ground_station.event_log import read_events
from bearcat.bus import keys
from bearcat.bus.identity import make_authority
from bearcat.netem.kernel.commands import namespace_of
from bearcat.runtime.peer_commands import vehicle_command
from bearcat.scenarios.schema import load_scenario
from tests.support.live_runs import game_started, wait_for
from tests.support.machines import Machines
from tests.support.scenario_files import scenario_text
from tests.support.system import missing_chromium, missing_namespaces

pytestmark = [
    pytest.mark.skipif(missing_namespaces() is not None, reason=str(missing_namespaces())),
    pytest.mark.xdist_group("kernel"),  # one worker looks at the host's links while namespaces come and go
]

GAME = "field-game"
PORT = 7447  # each machine has its own ports: the documented one is free
LEASE = 5.0
UAV = """
[[uav]]
id = "q1"
team = "attacker"
start = [25.0, 10.0]
altitude = 10.0
camera_radius = 8.0
search = "nearest"
"""
ROOT = Path(__file__).resolve().parents[1]
EAVESDROPPER = """
import json, sys, time
from tests.support.intruder import Intruder
endpoint, certs, seconds, *taps = sys.argv[1:]
with Intruder(endpoint, ca=f"{certs}/ca.pem", cert=f"{certs}/attacker.pem", key=f"{certs}/attacker.key") as player:
    for key in taps:
        player.tap(key)
    time.sleep(float(seconds))
    print(json.dumps(sorted({key for key, _, _ in player.heard})))
"""
NO_CERTIFICATE = """
import sys, zenoh
from tests.support.intruder import Intruder
try:
    Intruder(sys.argv[1], ca=sys.argv[2]).__exit__()
    print("connected")
except zenoh.ZError:
    print("refused")
"""


def bearcat(*argv: str) -> list[str]:
    return [sys.executable, "-m", "bearcat", *argv]


def host_links() -> set[tuple[str, int]]:
    """The host's links, less those of kernel-mode runs (``bcat*``): another
    run on this host may add one at any moment, and nothing this test starts
    can, for all of it runs inside the machines' namespaces."""
    links = json.loads(subprocess.run(["ip", "-j", "link"], capture_output=True, text=True).stdout)
    return {(link["ifname"], link["ifindex"]) for link in links if not link["ifname"].startswith("bcat")}


def _pids() -> list[int]:
    return [int(p.name) for p in Path("/proc").iterdir() if p.name.isdigit()]


def _namespace(pid: int) -> int | None:
    try:
        return namespace_of(pid)
    except (FileNotFoundError, ProcessLookupError, PermissionError):
        return None


def printed(launcher: subprocess.Popen, said: list[str], wanted: int) -> list[list[str]]:
    """The first ``wanted`` commands the launcher printed for peers on other machines, as this
    installation runs them (the launcher names the other machine's ``bearcat``)."""
    found = []
    for line in launcher.stdout:
        said.append(line)
        if line.startswith("  bearcat "):
            found.append(bearcat(*line.split()[1:]))
            if len(found) == wanted:
                return found
    pytest.fail(f"the launcher printed {len(found)} of {wanted} commands: {''.join(said)}")


@pytest.fixture(scope="module")
def field(tmp_path_factory):
    base = tmp_path_factory.mktemp("field")
    path = base / "game.toml"
    path.write_text(scenario_text(name=GAME, time_limit=14.0, netem="ideal", lease=LEASE) + UAV)
    scenario = load_scenario(path)
    out, certs = base / "run", base / "certs"
    foreign = make_authority(base / "foreign", {"attacker": "walker"})
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    before = host_links()
    found: dict = {"out": out, "said": []}
    with Machines("laptop", "companion", "stranger", "impostor") as net:
        laptop = net.address("laptop")
        found["laptop"], found["companion"] = laptop, net.address("companion")
        issued = subprocess.run(
            bearcat("certs", "init", str(certs), "--scenario", str(path), "--host", laptop),
            capture_output=True,
            text=True,
        )
        assert issued.returncode == 0, issued.stderr
        launcher = net.start(
            "laptop",
            bearcat("run", str(path), "--out", str(out), "--secure", "--certs", str(certs))
            + ["--listen", f"tls/{laptop}:{PORT}", "--joins", "attacker", "--joins", "q1"],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
        )
        walker, flyer = printed(launcher, found["said"], 2)
        found["commands"] = (walker, flyer)
        printing = {"stdout": subprocess.PIPE, "text": True, "env": env}  # what a program prints, not its logs
        there = found["companion disk"] = base / "companion"  # where the field computer keeps its own logs
        there.mkdir()
        net.start("companion", vehicle_command(scenario, 0, 14540), stdout=subprocess.DEVNULL, env=env)
        uav = net.start("companion", [*flyer, "--emulated"], stdout=subprocess.DEVNULL, env=env, cwd=there)
        person = net.start("companion", walker, stderr=subprocess.STDOUT, cwd=there, **printing)
        # While the game waits for them, strangers knock.
        stranger = net.start(
            "stranger",
            [sys.executable, "-c", NO_CERTIFICATE, f"tls/{laptop}:{PORT}", str(certs / "ca.pem")],
            cwd=ROOT,
            **printing,
        )
        found["no certificate"] = stranger.communicate(timeout=60)[0].strip()
        impostor = net.start(
            "impostor",
            bearcat("peer", "walker", "--scenario", f"zenoh:{GAME}", "--id", "attacker")
            + ["--connect", f"tls/{laptop}:{PORT}", "--certs", str(foreign), "--secure"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        _, found["impostor said"] = impostor.communicate(timeout=120)
        found["impostor exit"] = impostor.returncode
        assert wait_for(lambda: game_started(out), 300), "the game never started"
        # The attacker's certificate on a third machine, reading what it can.
        taps = [keys.guidance(GAME, "attacker"), keys.guidance(GAME, "defender"), keys.truth(GAME, "defender")]
        eavesdropper = net.start(
            "stranger",
            [sys.executable, "-c", EAVESDROPPER, f"tls/{laptop}:{PORT}", str(certs), "4", *taps],
            cwd=ROOT,
            **printing,
        )
        time.sleep(3.0)
        os.kill(uav.pid, signal.SIGKILL)
        found["killed"] = time.time()
        heard = eavesdropper.communicate(timeout=60)[0]
        found["eavesdropper heard"] = json.loads(heard.splitlines()[-1]) if heard.strip() else heard
        rest, _ = launcher.communicate(timeout=120)
        found["said"].append(rest)
        found["launcher exit"] = launcher.returncode
        found["walker said"], _ = person.communicate(timeout=30)
        found["walker exit"] = person.returncode
        namespaces = {namespace_of(pid) for pid in (net.pid(name) for name in net.names)}

    def left() -> list[int]:
        return [pid for pid in _pids() if _namespace(pid) in namespaces]

    wait_for(lambda: not left(), 5)  # a process SIGKILLed with its parent may take a moment to go
    found["left"] = left()
    found["links added"] = host_links() - before
    found["check"] = subprocess.run(bearcat("check", str(out)), capture_output=True, text=True)
    return found


def test_the_launcher_says_where_peers_elsewhere_join_and_what_they_run(field):
    said = "".join(field["said"])
    endpoint = f"tls/{field['laptop']}:{PORT}"
    assert f"router: peers on other machines join at {endpoint}" in said, said
    for command in field["commands"]:
        assert command[command.index("--scenario") + 1] == f"zenoh:{GAME}"  # fetched from the ground station
        assert command[command.index("--connect") + 1] == endpoint and "--secure" in command
    assert "--vehicle" in field["commands"][1]
    assert all("--hand-in" in command for command in field["commands"])


def test_the_log_of_a_peer_elsewhere_comes_back_sealed_and_the_killed_ones_is_said_missing(field):
    """The walker hands its log in at the end: the run keeps it with a seal
    naming its proven sender, and the field computer keeps its own copy. The
    UAV's peer, killed mid-game, hands in nothing, and the launcher says so
    after the lease. Then a byte changed in the kept log breaks ``logs``."""
    out = field["out"]
    kept = out / "peers" / "attacker.jsonl"
    assert kept.read_bytes() == (field["companion disk"] / "runs" / out.name / "peers" / "attacker.jsonl").read_bytes()
    seal = json.loads((out / "peers" / "attacker.seal.json").read_text())
    assert seal["sender"] == "attacker" and seal["proven"] and seal["bytes"] == kept.stat().st_size
    events = read_events(out / "events.jsonl")
    assert [e["peer"] for e in events if e["event"] == "handed-in"] == ["attacker"]
    assert [e["peer"] for e in events if e["event"] == "no-log"] == ["q1"]
    assert "q1 handed in no log within the lease" in "".join(field["said"])
    assert "and was handed to the launcher" in field["walker said"], field["walker said"]
    # The launcher's, the ground station's, the defender's and the attacker's handed in.
    assert re.search(r"held\s+logs\s+4 event log", field["check"].stdout), field["check"].stdout
    tampered = out.parent / "tampered"
    shutil.copytree(out, tampered)
    log = tampered / "peers" / "attacker.jsonl"
    log.write_bytes(log.read_bytes().replace(b'"attacker"', b'"attackeR"', 1))
    checked = subprocess.run(bearcat("check", str(tampered)), capture_output=True, text=True)
    assert "peers/attacker.jsonl is not the log attacker handed in" in checked.stdout, checked.stdout


def test_peers_on_another_machine_play_the_game_to_its_verdict_and_the_check_holds(field):
    assert field["launcher exit"] == 0, "".join(field["said"])
    outcome = json.loads((field["out"] / "outcome.json").read_text())
    assert outcome["ended"] and outcome["winner"] in ("attacker", "defender"), outcome
    assert "attacker" not in outcome["peers"] and "q1" not in outcome["peers"]  # theirs, not the launcher's
    assert field["check"].returncode == 0, field["check"].stdout
    assert re.search(r"held\s+verdict", field["check"].stdout), field["check"].stdout
    events = read_events(field["out"] / "events.jsonl")
    sent = [e for e in events if e["event"] == "sent"]
    assert sum(e["key"] == keys.fix(GAME, "attacker") for e in sent) >= 10  # its phone, about 1 Hz
    assert sum(e["key"] == keys.truth(GAME, "q1") for e in sent) > 5  # the UAV flew, from the other machine
    assert field["walker exit"] == 0 and "peer attacker: game ended" in field["walker said"], field["walker said"]


def test_the_launcher_reports_who_joined_from_where(field):
    said = "".join(field["said"])
    for name in ("attacker", "q1"):
        assert f"{GAME}: {name} joined from {field['companion']} on " in said, said
    joined = [e for e in read_events(field["out"] / "events.jsonl") if e["event"] == "joined"]
    assert {(e["name"], e["address"]) for e in joined} == {
        ("attacker", field["companion"]),
        ("q1", field["companion"]),
    }


def test_no_certificate_and_another_authoritys_cannot_connect(field):
    assert field["no certificate"] == "refused"
    assert field["impostor exit"] == 2
    assert field["impostor said"].splitlines() == [
        f"bearcat: error: session 'attacker' could not connect to tls/{field['laptop']}:{PORT}: the router's "
        f"certificate is not from the authority in {field['out'].parent / 'foreign' / 'ca.pem'} "
        "(certificate signature failure)"
    ]


def test_a_peer_elsewhere_is_held_to_the_access_rules_of_its_certificate(field):
    """With the attacker's certificate, a third machine hears the attacker's
    guidance and not the defender's, nor anyone's truth."""
    assert field["eavesdropper heard"] == [keys.guidance(GAME, "attacker")]


def test_a_remote_peer_killed_mid_game_is_seen_gone_within_the_lease(field):
    events = read_events(field["out"] / "events.jsonl")
    gone = [e["t"] for e in events if e["event"] == "gone" and e["key"] == keys.alive(GAME, "uav", "q1")]
    assert gone and 0 <= gone[0] - field["killed"] < LEASE, (gone, field["killed"])


def test_nothing_is_left_behind(field):
    assert field["left"] == []
    assert field["links added"] == set()
    assert re.search(r"held\s+leftovers", field["check"].stdout), field["check"].stdout


@pytest.mark.skipif(missing_chromium() is not None, reason=str(missing_chromium()))
def test_a_phone_on_the_field_network_opens_the_page_at_the_address_the_launcher_names(tmp_path):
    """The launcher serves the page on every interface of a laptop with no
    default route (a hotspot with no way out): the link it prints names
    the laptop's address on the field network, and Chromium on another
    machine opens it and plays to the end."""
    path = tmp_path / "game.toml"
    path.write_text(scenario_text(name=GAME, time_limit=8.0, netem="ideal"))
    lat, lon = load_scenario(path).map.to_geodetic(25.0, 22.0)  # where the attacker starts
    out = tmp_path / "run"
    with Machines("laptop", "phone") as net:
        launcher = net.start(
            "laptop",
            bearcat("run", str(path), "--out", str(out), "--phone", "attacker", "--page", "0.0.0.0:8443"),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=dict(os.environ, PYTHONUNBUFFERED="1"),
        )
        said = []
        for line in launcher.stdout:
            said.append(line)
            if link := re.search(r"open (https://\S+) on it", line):
                break
        else:
            pytest.fail(f"the launcher printed no link: {''.join(said)}")
        phone = net.start(
            "phone",
            [sys.executable, "-m", "tests.support.phone_page", link.group(1), str(lat), str(lon), "90"],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            text=True,
        )
        shown = json.loads(phone.communicate(timeout=180)[0])
        output, _ = launcher.communicate(timeout=120)
    assert link.group(1).startswith(f"https://{net.address('laptop')}:8443/?token="), link.group(1)
    assert launcher.returncode == 0, "".join(said) + output
    assert shown["status"] == 200 and shown["phase"] == "game over", shown
    events = read_events(out / "events.jsonl")
    assert any(e["event"] == "sent" and e["key"] == keys.fix(GAME, "attacker") for e in events)
