"""A peer's settings cross the process boundary as one typed value
(``runtime.peer_spec``): the flags a person types and the file the launcher
writes give the same spec, and a bad one is refused in one sentence."""

from __future__ import annotations

import argparse

import msgspec
import pytest

from bearcat.bus.errors import BusError
from bearcat.cli.main import build_parser, main
from bearcat.runtime.peer_spec import PeerSpec, flags, read_spec, spec_of, write_spec

EVERY_SETTING = PeerSpec(
    role="uav",
    scenario="zenoh:search",
    id="q1",
    connect=("tls/10.42.0.1:7447", "tls/10.42.0.2:7447"),
    listen=("tcp/127.0.0.1:0",),
    mode="client",
    seed=7,
    netem="3g",
    network="kernel",
    transport="udp",
    out="/tmp/run",
    certs="/tmp/certs",
    secure=True,
    faults="/tmp/run/faults.toml",
    resume=True,
    judge="fixes",
    provisional=True,
    vehicle="serial:///dev/ttyACM0:57600",
    sysid=2,
    emulated=True,
    page="127.0.0.1:9443",
    cert="/tmp/page.pem",
    key="/tmp/page.key",
    token_file="/tmp/token",
)


@pytest.mark.parametrize(
    "spec",
    [
        EVERY_SETTING,
        PeerSpec(role="ground-station", scenario="fake-out"),
        PeerSpec(role="walker", scenario="/tmp/game.toml", id="attacker", connect=("tcp/127.0.0.1:7447",)),
    ],
)
def test_the_flags_a_person_types_read_back_as_the_same_spec(spec):
    parser = build_parser("peer")
    args = parser.parse_args(["peer", *flags(spec)])
    assert spec_of(vars(args)) == spec
    # Every setting is a field the command line has a flag for, and every flag of the peer command is a field.
    (commands,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    settable = {a.dest for a in commands.choices["peer"]._actions if a.dest not in ("help", "spec")}
    assert settable == set(PeerSpec.__struct_fields__)


def test_a_spec_file_round_trips_and_a_bad_one_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "q1.spec.json"
    write_spec(path, EVERY_SETTING)
    assert read_spec(path) == EVERY_SETTING
    path.write_text(msgspec.json.encode({**msgspec.to_builtins(EVERY_SETTING), "sysid": "two"}).decode())
    with pytest.raises(BusError, match=r"q1.spec.json: not a peer spec: Expected `int \| null`, got `str`"):
        read_spec(path)
    path.write_text('{"role": "uav", "scenario": "search", "colour": "red"}')
    with pytest.raises(BusError, match="not a peer spec: Object contains unknown field `colour`"):
        read_spec(path)
    with pytest.raises(BusError, match="cannot read the peer's spec"):
        read_spec(tmp_path / "missing.json")


def test_bearcat_peer_needs_a_role_or_a_spec_and_not_both(tmp_path, capsys):
    assert main(["peer", "--scenario", "fake-out"]) == 2
    assert "bearcat peer needs a ROLE and --scenario SCENARIO, or --spec FILE" in capsys.readouterr().err
    path = tmp_path / "gs.spec.json"
    write_spec(path, PeerSpec(role="ground-station", scenario="fake-out"))
    assert main(["peer", "walker", "--spec", str(path)]) == 2
    assert "--spec FILE holds the peer's role and every setting" in capsys.readouterr().err
    path.write_text("{")
    assert main(["peer", "--spec", str(path)]) == 2
    assert "gs.spec.json: not a peer spec" in capsys.readouterr().err
