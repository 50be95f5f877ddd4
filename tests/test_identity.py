"""Seals and the access policy: on real Zenoh sessions over loopback, a
receiver believes a sender's name only when that sender's certificate key
signed the message, the policy lets it publish on that key, and the message
is newer than the last it took from that sender there."""

import os
import stat
import subprocess
import sys
import threading
import time

import msgspec
import pytest
import zenoh

from bearcat.bus import keys
from bearcat.bus.errors import BusError
from bearcat.bus.identity import Credentials, Refusal, make_authority, members_of
from bearcat.bus.policy import may_publish
from bearcat.bus.zenoh_session import ZenohSession, config
from bearcat.runtime.peer_commands import free_port

GAME = "g"
PEERS = {"gs": "ground-station", "launcher": "launcher", "attacker": "walker", "defender": "phone", "q1": "uav"}


@pytest.fixture(scope="module")
def authority(tmp_path_factory):
    return make_authority(tmp_path_factory.mktemp("certs") / "authority", PEERS)


def test_an_authority_issues_one_certificate_per_peer_with_its_role_and_private_keys_only_its_owner_reads(authority):
    found = members_of(authority)
    assert {name: m.role for name, m in found.items()} == PEERS
    assert stat.S_IMODE(os.stat(authority / "attacker.key").st_mode) == 0o600
    assert stat.S_IMODE(os.stat(authority).st_mode) == 0o700
    with pytest.raises(BusError, match="already holds a certificate authority"):
        make_authority(authority, {"x": "walker"})


def test_a_seal_opens_only_for_the_key_and_payload_its_sender_signed(authority):
    gs, attacker = Credentials(authority, "gs"), Credentials(authority, "attacker")
    key = keys.state(GAME)
    seal = gs.seal(key, b"running")
    member, n = attacker.open(key, b"running", seal)
    assert member.name == "gs" and member.role == "ground-station" and n > 0
    for other_key, payload in ((key, b"ended"), (keys.control(GAME), b"running")):
        with pytest.raises(Refusal) as refused:
            attacker.open(other_key, payload, seal)
        assert refused.value.category == "forged"
    _, n, signature = msgspec.msgpack.decode(seal)
    claimed = msgspec.msgpack.encode(["launcher", n, signature])  # gs's signature under another name
    with pytest.raises(Refusal, match="'launcher', who did not sign it"):
        attacker.open(key, b"running", claimed)
    assert gs.seal(key, b"x") != gs.seal(key, b"x")  # the count grows with every message


def test_a_certificate_from_another_authority_names_nobody(authority, tmp_path):
    other = make_authority(tmp_path / "other", {"gs": "ground-station"})
    (authority.parent / "mixed").mkdir()
    mixed = authority.parent / "mixed"
    for name in ("ca.pem", "attacker.pem", "attacker.key"):
        (mixed / name).write_bytes((authority / name).read_bytes())
    (mixed / "gs.pem").write_bytes((other / "gs.pem").read_bytes())
    assert set(members_of(mixed)) == {"attacker"}
    foreign = Credentials(other, "gs").seal(keys.state(GAME), b"x")
    with pytest.raises(Refusal) as refused:
        Credentials(mixed, "attacker").open(keys.state(GAME), b"x", foreign)
    assert refused.value.category == "unknown sender"
    with pytest.raises(BusError, match="no valid certificate for 'gs'"):
        Credentials(mixed, "gs")


@pytest.mark.parametrize(
    ("role", "name", "key", "allowed"),
    [
        ("ground-station", "gs", keys.state(GAME), True),
        ("ground-station", "gs", keys.guidance(GAME, "attacker"), True),
        ("ground-station", "gs", keys.control(GAME), False),
        ("ground-station", "gs", keys.truth(GAME, "attacker"), False),
        ("launcher", "launcher", keys.control(GAME), True),
        ("launcher", "launcher", keys.state(GAME), False),
        ("walker", "attacker", keys.fix(GAME, "attacker"), True),
        ("walker", "attacker", keys.truth(GAME, "attacker"), True),
        ("walker", "attacker", keys.fix(GAME, "defender"), False),
        ("walker", "attacker", keys.truth(GAME, "defender"), False),
        ("walker", "attacker", keys.state(GAME), False),
        ("walker", "attacker", keys.control(GAME), False),
        ("phone", "defender", keys.fix(GAME, "defender"), True),
        ("phone", "defender", keys.truth(GAME, "defender"), False),
        ("uav", "q1", keys.detection(GAME, "q1"), True),
        ("uav", "q1", keys.detection(GAME, "q2"), False),
        ("uav", "q1", keys.uav_task(GAME, "q1"), False),
        ("walker", "attacker", "not/a/bearcat/key", False),
    ],
)
def test_the_policy_lets_each_role_publish_only_its_own(role, name, key, allowed):
    assert may_publish(role, name, key) is allowed


def _client(authority, name, port):
    endpoint = f"tcp/127.0.0.1:{port}"
    return ZenohSession(
        name, config(listen=[], connect=[endpoint], mode="client"), credentials=Credentials(authority, name)
    )


def _pair(authority):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    hub = ZenohSession("gs", config(listen=[endpoint], mode="router"), credentials=Credentials(authority, "gs"))
    return port, hub, _client(authority, "attacker", port)


def _collect(session, key_expr):
    got, refusals = [], []
    lock = threading.Lock()
    session.subscribe(key_expr, lambda k, p, s: (lock.acquire(), got.append((k, p, s)), lock.release()))
    session.on_refused = lambda *r: refusals.append(r)
    return got, refusals


def _eventually(predicate, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end and not predicate():
        time.sleep(0.02)
    return predicate()


def test_sealed_sessions_believe_each_other_and_refuse_a_stranger_a_forger_and_a_replay(authority):
    port, hub, peer = _pair(authority)
    with hub, peer:
        got, refusals = _collect(hub, keys.game_wide(GAME))
        stranger_config = zenoh.Config()
        stranger_config.insert_json5("mode", '"client"')
        stranger_config.insert_json5("connect/endpoints", f'["tcp/127.0.0.1:{port}"]')
        stranger_config.insert_json5("scouting/multicast/enabled", "false")
        recorded = []
        with zenoh.open(stranger_config) as stranger:
            tap = stranger.declare_subscriber(keys.fix(GAME, "attacker"), lambda s: recorded.append(s))
            time.sleep(0.5)
            peer.put(keys.fix(GAME, "attacker"), b"first")
            assert _eventually(lambda: len(got) == 1 and recorded)
            assert got[0] == (keys.fix(GAME, "attacker"), b"first", "attacker")
            genuine = recorded[0]
            stranger.put(keys.fix(GAME, "attacker"), b"plain", attachment=b"attacker")
            _, n, signature = msgspec.msgpack.decode(genuine.attachment.to_bytes())
            later = msgspec.msgpack.encode(["attacker", n + 10, signature])  # a count the signature does not cover
            stranger.put(keys.fix(GAME, "attacker"), b"swapped", attachment=later)
            stranger.put(keys.fix(GAME, "attacker"), b"first", attachment=genuine.attachment.to_bytes())
            assert _eventually(lambda: len(refusals) == 3)
            tap.undeclare()
        peer.put(keys.state(GAME), b"the attacker says it won")  # sealed, but not the attacker's to say
        peer.put(keys.fix(GAME, "attacker"), b"second")
        assert _eventually(lambda: len(got) == 2 and len(refusals) == 4)
    assert got[1] == (keys.fix(GAME, "attacker"), b"second", "attacker")
    assert [(claimed, category) for _, claimed, category, _ in refusals] == [
        ("attacker", "bad seal"),
        ("attacker", "forged"),
        ("attacker", "replayed"),
        ("attacker", "not allowed"),
    ]
    assert hub.refusals == {"bad seal": 1, "forged": 1, "replayed": 1, "not allowed": 1}


def test_a_peer_fetches_the_map_only_from_a_provable_ground_station(authority):
    _, hub, peer = _pair(authority)
    with hub, peer:
        hub.serve(keys.map_query(GAME), lambda: b"the map")
        time.sleep(0.3)
        assert peer.fetch(keys.map_query(GAME)) == b"the map"
    port, hub, asker = _pair(authority)
    # The defender's own certificate serves a map: sealed, but not a ground station's to serve.
    with hub, asker, _client(authority, "defender", port) as liar:
        liar.serve(keys.map_query(GAME), lambda: b"a false map")
        time.sleep(0.3)
        assert asker.fetch(keys.map_query(GAME), timeout=1.0) is None
        assert asker.refusals == {"not allowed": 1}


def _bearcat(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "bearcat", *map(str, args)], capture_output=True, text=True, timeout=120, cwd=cwd
    )


def test_bearcat_certs_issues_what_a_scenario_lacks_and_lists_who_holds_what(tmp_path):
    made = _bearcat("certs", "init", tmp_path / "field", "--scenario", "fake-out", "--phone", "attacker")
    assert made.returncode == 0, made.stderr
    assert {line.split()[-1] for line in made.stdout.splitlines()} == {"gs", "launcher", "attacker", "defender"}
    again = _bearcat("certs", "init", tmp_path / "field", "--scenario", "search")
    assert again.returncode == 0 and again.stdout.split() == [f"{tmp_path / 'field' / 'q1'}.pem", "uav", "q1"]
    listed = _bearcat("certs", "list", tmp_path / "field").stdout.splitlines()
    assert [line.split()[:2] for line in listed] == [
        ["attacker", "phone"],
        ["defender", "walker"],
        ["gs", "ground-station"],
        ["launcher", "launcher"],
        ["q1", "uav"],
    ]
    wrong = _bearcat("certs", "init", tmp_path / "other", "--scenario", "fake-out", "--phone", "nobody")
    assert wrong.returncode == 2 and "there is no agent 'nobody' to give a phone" in wrong.stderr


def test_a_run_refuses_certificates_that_do_not_fit_it_in_one_sentence(tmp_path):
    _bearcat("certs", "init", tmp_path / "field", "--scenario", "fake-out", "--phone", "attacker")
    as_walker = _bearcat("run", "fake-out", "--certs", tmp_path / "field", "--out", tmp_path / "run")
    assert as_walker.returncode == 2
    assert "the certificate of 'attacker'" in as_walker.stderr and "is for a phone, not a walker" in as_walker.stderr
    over_udp = _bearcat("run", "fake-out", "--secure", "--transport", "udp", "--out", tmp_path / "run")
    assert over_udp.returncode == 2 and "transport 'udp' cannot be secured" in over_udp.stderr
    bare = _bearcat(
        "peer", "walker", "--scenario", "fake-out", "--id", "attacker", "--secure", "--connect", "tls/127.0.0.1:1"
    )
    assert bare.returncode == 2 and "a --secure peer needs --certs DIR" in bare.stderr
