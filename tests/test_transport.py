"""Best-effort messages over udp/, everything else over tcp/: a peer given a
best-effort session sends fixes and guidance there, subscribes to each kind
on the session it travels on, and receives every message exactly once."""

import os
import socket
import subprocess
import threading
import time
from contextlib import contextmanager

import pytest

from bearcat.bus import keys
from bearcat.bus.errors import BusError
from bearcat.bus.zenoh_session import ZenohSession, best_effort_endpoint, config
from tests.support.system import missing_iptables

GAME = "g"
PAYLOAD = b"p" * 500
COUNT = 200


def free_port() -> int:
    with socket.socket() as tcp, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        tcp.bind(("127.0.0.1", 0))
        port = tcp.getsockname()[1]
        udp.bind(("127.0.0.1", port))  # free for both protocols
        return port


def wait(predicate, timeout=5.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end and not predicate():
        time.sleep(0.01)
    return predicate()


@contextmanager
def star(transport: str):
    """A router listening on tcp/ and udp/, and two clients of it over ``transport``."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"

    def client(name):
        best_effort = None
        if transport == "udp":
            best_effort = config(listen=[], connect=[best_effort_endpoint(endpoint)], mode="client")
        return ZenohSession(name, config(listen=[], connect=[endpoint], mode="client"), best_effort=best_effort)

    with (
        ZenohSession("router", config(listen=[endpoint, best_effort_endpoint(endpoint)], mode="router")),
        client("a1") as sender,
        client("gs") as receiver,
    ):
        yield endpoint, sender, receiver


@pytest.mark.parametrize("transport", ["tcp", "udp"])
def test_a_wildcard_subscriber_gets_every_message_once(transport):
    with star(transport) as (_, sender, receiver):
        got = []
        receiver.subscribe(keys.game_wide(GAME), lambda k, p, s: got.append((k, s)))
        receiver.subscribe(keys.every(GAME, "fix"), lambda k, p, s: got.append(("fix only", s)))
        time.sleep(0.5)  # the subscriptions reach the router
        for _ in range(20):
            sender.put(keys.fix(GAME, "a1"), PAYLOAD, reliable=False)
            sender.put(keys.state(GAME), PAYLOAD)
            time.sleep(0.005)
        assert wait(lambda: len(got) >= 60)
        time.sleep(0.3)
        assert set(got) == {("fix only", "a1"), (keys.fix(GAME, "a1"), "a1"), (keys.state(GAME), "a1")}
        assert len(got) == 60, "a message arrived twice, or not at all"


@contextmanager
def counted(port: int):
    """Counters of the bytes sent to ``port`` over tcp and over udp on the loopback (iptables, root)."""
    chain = f"bc-test-{os.getpid()}"
    rules = [["-p", protocol, "--dport", str(port)] for protocol in ("tcp", "udp")]
    subprocess.run(["iptables", "-N", chain], check=True, capture_output=True)
    try:
        for rule in rules:
            subprocess.run(["iptables", "-A", chain, *rule], check=True, capture_output=True)
        subprocess.run(["iptables", "-I", "OUTPUT", "-o", "lo", "-j", chain], check=True, capture_output=True)

        def read() -> dict[str, int]:
            listing = subprocess.run(
                ["iptables", "-L", chain, "-v", "-n", "-x"], check=True, capture_output=True, text=True
            ).stdout.splitlines()[2:]
            return {("tcp" if " tcp dpt:" in line else "udp"): int(line.split()[1]) for line in listing}

        yield read
    finally:
        subprocess.run(["iptables", "-D", "OUTPUT", "-o", "lo", "-j", chain], capture_output=True)
        subprocess.run(["iptables", "-F", chain], capture_output=True)
        subprocess.run(["iptables", "-X", chain], capture_output=True)


@pytest.mark.skipif(missing_iptables() is not None, reason=f"counting packets by protocol {missing_iptables()}")
def test_fixes_travel_over_udp_and_state_over_tcp():
    with star("udp") as (endpoint, sender, receiver):
        got = []
        receiver.subscribe(keys.game_wide(GAME), lambda k, p, s: got.append(k))
        time.sleep(0.5)
        port = int(endpoint.rsplit(":", 1)[1])
        with counted(port) as read:
            for kind, key, reliable in (("fix", keys.fix(GAME, "a1"), False), ("state", keys.state(GAME), True)):
                before = read()
                for _ in range(COUNT):
                    sender.put(key, PAYLOAD, reliable=reliable)
                    time.sleep(0.002)
                assert wait(lambda key=key: got.count(key) == COUNT), f"not every {kind} arrived"
                after = read()
                carried = {protocol: after[protocol] - before[protocol] for protocol in ("tcp", "udp")}
                payload = COUNT * len(PAYLOAD)
                # Counted on the way to the router's port, once per message.
                on, off = ("udp", "tcp") if kind == "fix" else ("tcp", "udp")
                assert carried[on] >= payload, (kind, carried)
                assert carried[off] < 0.1 * payload, (kind, carried)  # keep-alives only


def test_a_udp_client_keeps_trying_until_its_router_answers():
    """Zenoh does not retransmit its handshake over udp/, so one lost packet
    (here: no router yet) must not end a phone's attempt to join."""
    endpoint = f"udp/127.0.0.1:{free_port()}"
    router = threading.Timer(
        1.5, lambda: opened.append(ZenohSession("router", config(listen=[endpoint], mode="router")))
    )
    opened = []
    router.start()
    try:
        started = time.monotonic()
        with ZenohSession("a1", config(listen=[], connect=[endpoint], mode="client")) as phone:
            assert time.monotonic() - started >= 1.0  # it opened once the router was there, not before
            assert not phone.closed
    finally:
        router.join()
        for session in opened:
            session.close()


def test_a_tcp_client_without_a_router_is_refused_at_once():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    started = time.monotonic()
    with pytest.raises(BusError, match=endpoint):
        ZenohSession("a1", config(listen=[], connect=[endpoint], mode="client"))
    assert time.monotonic() - started < 5.0  # a refused TCP connection is an answer: no waiting for retries
