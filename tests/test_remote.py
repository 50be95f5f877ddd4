"""Peers on other machines, the parts that need no second machine: the
endpoints a router takes them on, what its certificate must name, what
each is told, who joined from where, and the one sentence a mistake or a
link that will not open gets (``tests/test_field_network.py`` plays a game
across two machines)."""

import subprocess
import sys
from types import SimpleNamespace

import pytest

from bearcat.bus.endpoints import Endpoint, check_host, parse_endpoint
from bearcat.bus.errors import BusError
from bearcat.bus.identity import Credentials, hosts_named, make_authority
from bearcat.bus.zenoh_session import Link, ZenohSession, config
from bearcat.runtime import remote
from bearcat.runtime.peer_commands import free_port
from tests.support.scenario_files import write_scenario


def _bearcat(*args):
    return subprocess.run(
        [sys.executable, "-m", "bearcat", *map(str, args)], capture_output=True, text=True, timeout=120
    )


@pytest.mark.parametrize(
    ("text", "parsed"),
    [
        ("tls/0.0.0.0:7447", Endpoint("tls", "0.0.0.0", 7447)),
        ("tcp/192.168.1.10:7447", Endpoint("tcp", "192.168.1.10", 7447)),
        ("tls/[fe80::1]:7447", Endpoint("tls", "fe80::1", 7447)),
        ("tls/Field-Laptop.local:7447", Endpoint("tls", "field-laptop.local", 7447)),
    ],
)
def test_an_endpoint_reads_as_protocol_host_and_port_and_writes_back(text, parsed):
    assert parse_endpoint(text) == parsed
    assert parse_endpoint(str(parsed)) == parsed


@pytest.mark.parametrize(
    ("text", "culprit"),
    [
        ("192.168.1.10:7447", "is not of the form PROTOCOL/HOST:PORT"),
        ("tls/192.168.1.10", "is not of the form PROTOCOL/HOST:PORT"),
        ("quic/192.168.1.10:7447", "protocol 'quic' is not one of tcp, tls, udp"),
        ("tls/192.168.1.10:74470", "port '74470' is not a number from 0 to 65535"),
        ("tls/192.168.1:7447", "host '192.168.1' is not an IP address"),
        ("tls/10.0.0.300:7447", "host '10.0.0.300' is not an IP address"),
        ("tls/field laptop:7447", "host 'field laptop' is neither an IP address nor a DNS name"),
        ("tls/fe80::1:7447", "an IPv6 address goes in brackets"),
        ("tls/[10.0.0.1]:7447", "only an IPv6 address goes in brackets"),
    ],
)
def test_a_malformed_endpoint_is_one_sentence_naming_it(text, culprit):
    with pytest.raises(BusError, match="endpoint") as refused:
        parse_endpoint(text)
    assert repr(text) in str(refused.value) and culprit in str(refused.value)


def test_a_host_is_an_address_or_a_dns_name():
    assert check_host("192.168.1.10") == "192.168.1.10"
    assert check_host("Field.example.") == "field.example"
    for bad in ("", "-x", "a..b", "x" * 64, "1.2.3"):
        with pytest.raises(BusError):
            check_host(bad)


def test_a_router_listens_on_tls_when_secure_and_on_tcp_and_udp_when_not():
    everywhere, one = parse_endpoint("tls/0.0.0.0:7447"), parse_endpoint("tcp/192.168.1.10:7447")
    remote.check_listen((everywhere,), secure=True)
    remote.check_listen((one,), secure=False)
    assert remote.router_endpoints((everywhere,), secure=True) == ["tls/0.0.0.0:7447"]
    assert remote.router_endpoints((one,), secure=False) == ["tcp/192.168.1.10:7447", "udp/192.168.1.10:7447"]
    for text, secure, said in (
        ("tcp/0.0.0.0:7447", True, "a --secure router takes tls/ links only, e.g. tls/0.0.0.0:7447"),
        ("tls/0.0.0.0:7447", False, "tls/ needs --secure, e.g. tcp/0.0.0.0:7447"),
        ("udp/0.0.0.0:7447", False, "takes tcp/ links"),
        ("tls/laptop.local:7447", True, "an address of this machine, not on a name"),
        ("tls/0.0.0.0:0", True, "need a port they know"),
    ):
        with pytest.raises(BusError, match="--listen") as refused:
            remote.check_listen((parse_endpoint(text),), secure=secure)
        assert said in str(refused.value)


def test_peers_elsewhere_join_at_each_address_the_router_certificate_names():
    addresses = ("192.168.1.10", "10.42.0.1")
    everywhere, one = parse_endpoint("tls/0.0.0.0:7447"), parse_endpoint("tls/10.42.0.1:7447")
    assert remote.hosts((everywhere,), addresses) == addresses  # a run's own certificate names them all
    assert remote.hosts((one, parse_endpoint("tls/127.0.0.2:7448")), addresses) == ("10.42.0.1", "127.0.0.2")
    assert [str(e) for e in remote.reachable_at((everywhere,), addresses)] == [
        "tls/192.168.1.10:7447",
        "tls/10.42.0.1:7447",
    ]
    named = ("localhost", "127.0.0.1", "10.42.0.1", "laptop.field")
    assert [str(e) for e in remote.reachable_at((everywhere,), addresses, named)] == [
        "tls/10.42.0.1:7447",
        "tls/laptop.field:7447",
    ]
    remote.uncovered((everywhere, one), addresses, named, "DIR/launcher.pem")
    with pytest.raises(BusError, match=r"DIR/launcher.pem does not name 192.168.1.10, where --listen tls/192"):
        remote.uncovered((parse_endpoint("tls/192.168.1.10:7447"),), addresses, named, "DIR/launcher.pem")
    with pytest.raises(BusError, match=r"names none of this machine's addresses \(192.168.1.10\)"):
        remote.uncovered((everywhere,), ("192.168.1.10",), ("localhost", "127.0.0.1"), "DIR/launcher.pem")


def test_a_phone_is_told_the_address_of_the_field_network_not_the_loopback():
    field = (parse_endpoint("tls/0.0.0.0:7448"), parse_endpoint("tls/10.42.0.1:7447"))
    assert remote.link_host("192.168.1.10", field) == "192.168.1.10"  # asked for
    assert remote.link_host("127.0.0.1", ()) == "127.0.0.1"  # asked for, behind a tunnel
    assert remote.link_host("0.0.0.0", field) == "10.42.0.1"
    assert remote.link_host("0.0.0.0", (parse_endpoint("tls/127.0.0.1:7447"),)) is None  # the machine's to say


def test_who_joined_from_where_is_said_once_per_name_and_address():
    links = [
        Link("tls/192.168.1.20:40112", ("wlan0",), "q1"),
        Link("tls/127.0.0.1:40113", ("lo",), "gs"),  # on this machine
        Link("tcp/192.168.1.21:40114", (), None),
    ]
    seen: set = set()
    found = remote.arrivals(links, seen)
    assert [a.describe() for a in found] == [
        "q1 joined from 192.168.1.20 on wlan0",
        "a peer (an unsecured link does not say who) joined from 192.168.1.21",
    ]
    again = [Link("tls/192.168.1.20:40200", ("wlan0",), "q1")]  # its fetch, then its session
    assert remote.arrivals(again, seen) == []


def test_a_peer_a_person_starts_on_this_machine_is_said_to_join_by_its_certificates_name():
    links = [
        Link("tls/127.0.0.1:40113", ("lo",), "gs"),  # the launcher's own
        Link("tls/127.0.0.1:40114", ("lo",), "defender"),  # --joins defender
        Link("tcp/127.0.0.1:40115", ("lo",), None),  # unsecured: nobody can say it is the defender
    ]
    found = remote.arrivals(links, set(), frozenset({"defender"}))
    assert [a.describe() for a in found] == ["defender joined from 127.0.0.1 on lo"]


def test_certs_init_host_puts_an_address_in_the_routers_certificate_even_once_issued(tmp_path):
    made = _bearcat("certs", "init", tmp_path / "field", "--scenario", "fake-out")
    assert made.returncode == 0, made.stderr
    assert "192.168.1.10" not in hosts_named(tmp_path / "field", "launcher")
    gs = (tmp_path / "field" / "gs.pem").read_bytes()
    added = _bearcat("certs", "init", tmp_path / "field", "--scenario", "fake-out", "--host", "192.168.1.10")
    assert added.returncode == 0, added.stderr
    assert added.stdout.splitlines() == [
        f"{tmp_path / 'field' / 'launcher'}.pem  launcher launcher",
        "the router's certificate names localhost, 127.0.0.1, 192.168.1.10",
    ]
    assert (tmp_path / "field" / "gs.pem").read_bytes() == gs  # the others keep theirs
    listed = _bearcat("certs", "list", tmp_path / "field").stdout
    assert "(router at localhost, 127.0.0.1, 192.168.1.10)" in listed, listed
    Credentials(tmp_path / "field", "launcher")  # the new certificate goes with its new key
    for bad, said in (("192.168.1", "is not an IP address"), ("0.0.0.0", "means every interface")):
        refused = _bearcat("certs", "init", tmp_path / "field", "--scenario", "fake-out", "--host", bad)
        assert refused.returncode == 2 and said in refused.stderr and "Traceback" not in refused.stderr


def test_a_run_refuses_a_listen_endpoint_it_could_not_take_peers_on_in_one_sentence(tmp_path):
    scenario = write_scenario(tmp_path)
    _bearcat("certs", "init", tmp_path / "field", "--scenario", scenario)
    for flags, said in (
        (["--listen", "tls/192.168.1:7447"], "argument --listen: endpoint 'tls/192.168.1:7447': host '192.168.1'"),
        (["--secure", "--listen", "tcp/0.0.0.0:7447"], "a --secure router takes tls/ links only"),
        (
            ["--secure", "--certs", tmp_path / "field", "--listen", "tls/127.0.0.2:7447"],
            f"the router's certificate {tmp_path / 'field' / 'launcher.pem'} does not name 127.0.0.2",
        ),
        (["--joins", "q7"], "there is no agent or UAV 'q7' to join by hand"),
        (["--listen", "tcp/203.0.113.9:7447"], "no interface of this machine has the address 203.0.113.9"),
    ):
        run = _bearcat("run", scenario, "--out", tmp_path / "run", *flags)
        assert run.returncode == 2 and said in run.stderr, run.stderr
        assert len(run.stderr.strip().splitlines()) == 1 or "usage:" in run.stderr
        assert not (tmp_path / "run").exists()


@pytest.fixture(scope="module")
def router(tmp_path_factory):
    """A guarded router on the loopback, at 127.0.0.1 and at 127.0.0.2, which its certificate does not name."""
    base = tmp_path_factory.mktemp("router")
    ours = make_authority(base / "ours", {"launcher": "launcher", "attacker": "walker"})
    port = free_port()
    with ZenohSession(
        "launcher",
        config(
            listen=[f"tls/127.0.0.1:{port}", f"tls/127.0.0.2:{port}"], mode="router", tls=Credentials(ours, "launcher")
        ),
    ) as session:
        yield base, ours, port, session


def _join(directory, endpoint: str, name: str = "attacker") -> str:
    """What opening a guarded client session as ``name`` with the certificates in ``directory`` came to."""
    identity = SimpleNamespace(  # what Credentials would hold, had the authority issued the certificate
        authority=directory / "ca.pem", certificate=directory / f"{name}.pem", private_key=directory / f"{name}.key"
    )
    try:
        with ZenohSession(name, config(listen=[], connect=[endpoint], mode="client", tls=identity)):
            return "joined"
    except BusError as exc:
        return str(exc)


def test_a_link_that_will_not_open_says_which_end_to_fix(router):
    base, ours, port, _ = router
    theirs = make_authority(base / "theirs", {"attacker": "walker"})
    mixed = base / "mixed"  # our authority, a certificate of theirs
    mixed.mkdir()
    for name, source in (("ca.pem", ours), ("attacker.pem", theirs), ("attacker.key", theirs)):
        (mixed / name).write_bytes((source / name).read_bytes())
    at = f"tls/127.0.0.1:{port}"
    assert _join(ours, at) == "joined"
    nowhere = f"tls/127.0.0.1:{free_port()}"
    said = f"session 'attacker' could not connect to {nowhere}: nothing answered there (Connection refused)"
    assert _join(ours, nowhere) == said
    assert _join(theirs, at) == (
        f"session 'attacker' could not connect to {at}: the router's certificate is not from the authority in "
        f"{theirs / 'ca.pem'} (certificate signature failure)"
    )
    assert _join(ours, f"tls/127.0.0.2:{port}").endswith(
        "the router's certificate does not name 127.0.0.2: on the router's machine, "
        "bearcat certs init DIR --scenario SCENARIO --host 127.0.0.2 adds it"
    )
    assert f"the router refused this peer's certificate {mixed / 'attacker.pem'}" in _join(mixed, at)


def test_the_router_knows_who_joined_over_tls_and_from_where(router):
    _, ours, port, session = router
    credentials = Credentials(ours, "attacker")
    with ZenohSession("attacker", config(listen=[], connect=[f"tls/127.0.0.1:{port}"], mode="client", tls=credentials)):
        (link,) = session.links()
    assert link.certificate == "attacker" and link.remote.startswith("tls/127.0.0.1:") and link.interfaces == ("lo",)
