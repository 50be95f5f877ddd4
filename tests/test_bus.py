"""Keys, messages and codec, the in-process bus, and real Zenoh sessions on
loopback: what goes in comes out, with the sender; what is malformed is
dropped, counted and never raised into a peer."""

import math
import socket
import time

import msgspec
import pytest
import zenoh
from hypothesis import given, settings
from hypothesis import strategies as st

from bearcat.bus import keys
from bearcat.bus.codec import MAX_PAYLOAD, Inbox, Refused, decode, encode
from bearcat.bus.errors import BusError
from bearcat.bus.inprocess import InProcessBus
from bearcat.bus.messages import Control, Fix, GameState, Guidance, Report, Truth, UavTask
from bearcat.bus.zenoh_session import ZenohSession, config

GAME = "g1"

SAMPLES = {
    keys.fix(GAME, "a1"): Fix(agent="a1", seq=3, t=12.5, lat=37.87, lon=-122.26, heading=359.5, accuracy=4.0),
    keys.truth(GAME, "a1"): Truth(agent="a1", t=12.5, lat=37.87, lon=-122.26),
    keys.guidance(GAME, "d1"): Guidance(
        agent="d1",
        seq=1,
        t=12.6,
        game="ctf",
        heading=90.0,
        region=[[(-122.0, 37.0), (-122.0, 37.1), (-122.1, 37.1)]],
        region_of="a1",
        go=False,
        value=3.5,
        reports=[Report("a1", 12.5, 37.87, -122.26)],
    ),
    keys.state(GAME): GameState(seq=7, t=20.0, phase="ended", winner="defender", reason="capture", captured=["a1"]),
    keys.control(GAME): Control(t=0.0, command="start"),
    keys.uav_task(GAME, "q1"): UavTask(uav="q1", seq=0, t=1.0, kind="search", lat=37.87, lon=-122.26, alt=30.0),
}


# ---------------------------------------------------------------------- keys


def test_every_builder_parses_back_to_its_kind_and_names():
    assert keys.parse(keys.fix(GAME, "a1")) == keys.ParsedKey("fix", GAME, agent="a1")
    assert keys.parse(keys.uav_task(GAME, "q1")) == keys.ParsedKey("uav-task", GAME, agent="q1")
    assert keys.parse(keys.alive(GAME, "walker", "w1")) == keys.ParsedKey("alive", GAME, agent="w1", role="walker")
    assert keys.parse(keys.state(GAME)).kind == "state"


@pytest.mark.parametrize("name", ["a/b", "*", "**", "", "a b", "x" * 65, "é"])
def test_a_name_that_would_widen_or_break_a_key_is_refused(name):
    with pytest.raises(BusError, match="agent"):
        keys.fix(GAME, name)


@pytest.mark.parametrize("kind", ["fix", "guidance", "truth", "uav-task", "alive", "state"])
def test_the_wildcard_of_a_kind_matches_its_keys_and_no_other(kind):
    concrete = {
        "fix": keys.fix(GAME, "a1"),
        "guidance": keys.guidance(GAME, "a1"),
        "truth": keys.truth(GAME, "a1"),
        "uav-task": keys.uav_task(GAME, "q1"),
        "alive": keys.alive(GAME, "phone", "a1"),
        "state": keys.state(GAME),
    }
    wildcard = zenoh.KeyExpr(keys.every(GAME, kind))
    for other, key in concrete.items():
        assert wildcard.includes(zenoh.KeyExpr(key)) == (other == kind)


@pytest.mark.parametrize("key", ["bearcat/g1/fix", "bearcat/g1/fix/a/b", "other/g1/state", "bearcat/g1/alive/pilot/a1"])
def test_parse_refuses_keys_that_are_not_ours(key):
    with pytest.raises(BusError, match="not a bearcat key"):
        keys.parse(key)


# ---------------------------------------------------------------------- codec


@pytest.mark.parametrize("key", list(SAMPLES))
def test_every_message_round_trips_on_its_key(key):
    assert decode(encode(SAMPLES[key]), key) == SAMPLES[key]


@given(
    seq=st.integers(0, 2**40),
    t=st.floats(0, 1e9),
    lat=st.floats(-90, 90),
    lon=st.floats(-180, 180),
    heading=st.none() | st.floats(0, 360, exclude_max=True),
)
def test_any_valid_fix_round_trips_exactly(seq, t, lat, lon, heading):
    fix = Fix(agent="a1", seq=seq, t=t, lat=lat, lon=lon, heading=heading)
    assert decode(encode(fix), keys.fix(GAME, "a1")) == fix


def _raw(**fields) -> bytes:
    return msgspec.msgpack.encode(
        {"type": "fix", "v": 1, "agent": "a1", "seq": 0, "t": 1.0, "lat": 0.0, "lon": 0.0} | fields
    )


@pytest.mark.parametrize(
    "payload, category",
    [
        (_raw(lat=math.nan), "undecodable"),
        (_raw(lon=math.inf), "undecodable"),
        (_raw(lat=91.0), "undecodable"),
        (_raw(heading=360.0), "undecodable"),
        (_raw(seq=-1), "undecodable"),
        (_raw(agent="a/b"), "undecodable"),
        (_raw(v=2), "undecodable"),
        (_raw(extra=1), "undecodable"),
        (_raw(type="nope"), "undecodable"),
        (b"\xc1", "undecodable"),
        (b"", "undecodable"),
        (_raw(agent="a2"), "wrong name"),
        (encode(SAMPLES[keys.state(GAME)]), "wrong kind"),
        (b"\x00" * (MAX_PAYLOAD + 1), "oversized"),
    ],
)
def test_a_bad_fix_is_refused_with_its_reason(payload, category):
    with pytest.raises(Refused) as refused:
        decode(payload, keys.fix(GAME, "a1"))
    assert refused.value.category == category


def test_a_guidance_with_too_many_rings_is_refused():
    ring = [(0.0, 0.0)] * 3
    payload = msgspec.msgpack.encode(
        {"type": "guidance", "agent": "a1", "seq": 0, "t": 0.0, "game": "ctf", "region": [ring] * 65}
    )
    with pytest.raises(Refused, match="length"):
        decode(payload, keys.guidance(GAME, "a1"))


@settings(max_examples=300)
@given(payload=st.binary(max_size=200), key=st.sampled_from([*SAMPLES, "bearcat/g1/nothing", "elsewhere"]))
def test_the_inbox_never_raises_and_counts_every_drop(payload, key):
    inbox = Inbox("test")
    message = inbox.accept(key, payload)
    assert inbox.received == 1
    assert (message is None) == (inbox.dropped == 1)


def test_the_inbox_counts_drops_by_reason():
    inbox = Inbox("test")
    key = keys.fix(GAME, "a1")
    for payload in (b"junk", b"junk", _raw(agent="a2"), encode(SAMPLES[key])):
        inbox.accept(key, payload)
    assert inbox.drops == {"undecodable": 2, "wrong name": 1}
    assert inbox.received == 4


# ---------------------------------------------------------------------- in-process bus


def test_in_process_subscribers_get_matching_puts_with_the_sender():
    bus = InProcessBus()
    a, b = bus.session("a"), bus.session("b")
    got = []
    b.subscribe(keys.every(GAME, "fix"), lambda k, p, s: got.append((k, p, s)))
    a.put(keys.fix(GAME, "a1"), b"x", reliable=False)
    a.put(keys.state(GAME), b"y")
    assert got == [(keys.fix(GAME, "a1"), b"x", "a")]


def test_in_process_puts_reach_whoever_subscribes_opens_or_closes_between_them():
    """Who receives a key is kept between puts: a subscription, a session and
    a close made after the first put still count from the next one on."""
    bus = InProcessBus()
    a, b = bus.session("a"), bus.session("b")
    got = []
    key = keys.state(GAME)
    a.put(key, b"1")
    b.subscribe(key, lambda k, p, s: got.append(("b", p)))
    a.put(key, b"2")
    c = bus.session("c")
    c.subscribe(keys.every(GAME, "state"), lambda k, p, s: got.append(("c", p)))
    b.subscribe(key, lambda k, p, s: got.append(("b again", p)))
    a.put(key, b"3")
    b.close()
    a.put(key, b"4")
    assert got == [("b", b"2"), ("b", b"3"), ("b again", b"3"), ("c", b"3"), ("c", b"4")]


def test_in_process_liveliness_has_history_and_vanishes_on_close():
    bus = InProcessBus()
    a, b = bus.session("a"), bus.session("b")
    a.declare_token(keys.alive(GAME, "walker", "a1"))
    seen = []
    b.subscribe_liveliness(keys.every(GAME, "alive"), lambda k, alive: seen.append(alive))
    assert seen == [True] and b.alive(keys.every(GAME, "alive")) == [keys.alive(GAME, "walker", "a1")]
    a.close()
    assert seen == [True, False] and b.alive(keys.every(GAME, "alive")) == []
    with pytest.raises(BusError, match="closed"):
        a.put(keys.state(GAME), b"")


def test_a_raising_subscriber_does_not_reach_the_sender_or_other_subscribers():
    bus = InProcessBus()
    a, b, c = bus.session("a"), bus.session("b"), bus.session("c")
    b.subscribe(keys.state(GAME), lambda k, p, s: 1 / 0)
    got = []
    c.subscribe(keys.state(GAME), lambda k, p, s: got.append(p))
    a.put(keys.state(GAME), b"z")
    assert got == [b"z"]


def test_a_deliver_hook_sees_every_delivery_and_can_defer_it():
    queued = []
    bus = InProcessBus(deliver=lambda *envelope: queued.append(envelope))
    a, b = bus.session("a"), bus.session("b")
    got = []
    b.subscribe(keys.state(GAME), lambda k, p, s: got.append(p))
    b.subscribe(keys.game_wide(GAME), lambda k, p, s: got.append(p))
    a.put(keys.state(GAME), b"later")
    assert got == [] and [e[:4] for e in queued] == [("a", "b", keys.state(GAME), b"later")]
    call = queued[0][4]
    call(b"later")
    call(b"twice")  # a duplicate reaches every matching subscriber again
    assert got == [b"later", b"later", b"twice", b"twice"]


# ---------------------------------------------------------------------- zenoh


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(predicate, timeout=3.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


@pytest.fixture
def zenoh_pair():
    port = _free_port()
    with (
        ZenohSession("hub", config(listen=[f"tcp/127.0.0.1:{port}"])) as hub,
        ZenohSession("leaf", config(connect=[f"tcp/127.0.0.1:{port}"])) as leaf,
    ):
        yield hub, leaf


def test_zenoh_delivers_fixes_and_state_with_the_sender_and_drops_garbage(zenoh_pair):
    hub, leaf = zenoh_pair
    inbox, got = Inbox("hub"), []
    hub.subscribe(keys.game_wide(GAME), lambda k, p, s: got.append((inbox.accept(k, p), s)))
    hub.subscribe_liveliness(keys.every(GAME, "alive"), lambda k, alive: None)
    leaf.declare_token(keys.alive(GAME, "phone", "a1"))
    assert _wait(lambda: hub.alive(keys.every(GAME, "alive")) == [keys.alive(GAME, "phone", "a1")])
    fix, state = SAMPLES[keys.fix(GAME, "a1")], SAMPLES[keys.state(GAME)]
    leaf.put(keys.fix(GAME, "a1"), encode(fix), reliable=False)
    leaf.put(keys.state(GAME), encode(state))
    leaf.put(keys.fix(GAME, "a1"), b"\xff garbage")
    leaf.put(keys.state(GAME), encode(fix))
    assert _wait(lambda: len(got) == 4)
    assert got[:2] == [(fix, "leaf"), (state, "leaf")]
    assert inbox.drops == {"undecodable": 1, "wrong kind": 1}
    assert hub.callback_errors == 0


def test_zenoh_liveliness_vanishes_within_two_seconds_of_a_close(zenoh_pair):
    """A requirement: the launcher and the referee must learn of a peer's exit
    within two seconds to end the game on time. A clean close is seen in
    milliseconds on loopback; two seconds is the link lease (1 s) with a full
    second of margin for a loaded 2-core machine."""
    hub, leaf = zenoh_pair
    events = []
    hub.subscribe_liveliness(keys.every(GAME, "alive"), lambda k, alive: events.append((time.monotonic(), alive)))
    leaf.declare_token(keys.alive(GAME, "walker", "w1"))
    assert _wait(lambda: [a for _, a in events] == [True])
    closed = time.monotonic()
    leaf.close()
    assert _wait(lambda: [a for _, a in events] == [True, False])
    assert events[-1][0] - closed < 2.0


def test_a_raising_zenoh_callback_is_counted_not_lost(zenoh_pair):
    hub, leaf = zenoh_pair
    hub.subscribe(keys.state(GAME), lambda k, p, s: 1 / 0)
    hub.declare_token(keys.alive(GAME, "referee", "gs"))
    assert _wait(lambda: leaf.alive(keys.every(GAME, "alive")) != [])
    time.sleep(0.2)  # the subscription's declaration reaches the leaf
    leaf.put(keys.state(GAME), b"x")
    assert _wait(lambda: hub.callback_errors == 1)


def test_a_zenoh_session_closes_when_its_block_ends_even_by_an_exception():
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    with ZenohSession("hub", config(listen=[endpoint])) as hub:
        seen = []
        hub.subscribe_liveliness(keys.every(GAME, "alive"), lambda k, alive: seen.append(alive))
        with pytest.raises(KeyError), ZenohSession("brief", config(connect=[endpoint])) as brief:
            brief.declare_token(keys.alive(GAME, "walker", "w2"))
            assert _wait(lambda: seen == [True])
            raise KeyError("out of the block")
        assert brief.closed and _wait(lambda: seen == [True, False])
    assert hub.closed
    with pytest.raises(BusError, match="'brief' is closed"):
        brief.put(keys.state(GAME), b"")


def test_a_bad_endpoint_is_named():
    with pytest.raises(BusError, match="localhost:7447"):
        config(connect=["localhost:7447"])


def test_a_sender_over_its_budget_gets_the_burst_then_the_rate_and_is_said_once_a_second():
    from bearcat.bus.budget import SenderBudget

    budget = SenderBudget(rate=100.0, burst=500.0)
    passed = sum(budget.allow("vandal", "k", k * 1e-4) for k in range(30_000))  # 10 kHz for 3 s
    assert 500 + 100 * 3 - 2 <= passed <= 500 + 100 * 3 + 2
    assert budget.allow("honest", "k", 3.0)  # another sender has a budget of its own
    assert budget.over[("vandal", "k")] == 30_000 - passed
    said = budget.news(3.0)
    assert said == {("vandal", "k"): 30_000 - passed} and budget.news(3.5) == {}
    steady = sum(budget.allow("phone", "fix", 10.0 + k / 50.0) for k in range(5_000))  # 50 Hz for 100 s
    assert steady == 5_000  # a legitimate stream never goes over


def test_a_flood_from_zenoh_threads_wakes_a_busy_loop_once_and_loses_nothing():
    """Ten thousand samples put from two threads while the loop is busy: one
    wake-up of its self-pipe (a byte each would fill it and lose a signal),
    every sample handled once, each thread's in order, past one that raises."""
    import asyncio
    import threading

    from bearcat.bus.handoff import Handoff

    async def flood():
        loop = asyncio.get_running_loop()
        wakeups = []
        wake = loop.call_soon_threadsafe
        loop.call_soon_threadsafe = lambda *a: (wakeups.append(1), wake(*a))
        handoff, seen = Handoff(loop), []

        def handle(source, k):
            if k == 3:
                raise ValueError("a bad sample")
            seen.append((source, k))

        threads = [threading.Thread(target=lambda s=s: [handoff.put(handle, s, k) for k in range(5000)]) for s in "ab"]
        for t in threads:
            t.start()
        for t in threads:
            t.join()  # the loop is busy here: nothing of the flood has run
        await asyncio.sleep(0.05)
        return wakeups, seen

    wakeups, seen = asyncio.run(flood())
    assert len(wakeups) == 1
    assert [k for s, k in seen if s == "a"] == [k for k in range(5000) if k != 3]
    assert [k for s, k in seen if s == "b"] == [k for k in range(5000) if k != 3]


def test_the_ground_stations_peer_name_is_spelled_once():
    """Its one definition is in the bus, the lowest floor that every user
    of it may import: no other module of the package writes ``"gs"``
    (scenario and fault files, data, may)."""
    import ast
    from pathlib import Path

    package = Path(keys.__file__).resolve().parent.parent
    spelled = [
        f"{path.relative_to(package.parent)}:{node.lineno}"
        for path in sorted(package.rglob("*.py"))
        for node in ast.walk(ast.parse(path.read_text(), str(path)))
        if isinstance(node, ast.Constant) and node.value == "gs"
    ]
    assert spelled == [f"bearcat/bus/keys.py:{_line_of(Path(keys.__file__), 'GROUND = ')}"]


def _line_of(path, text: str) -> int:
    return next((n for n, line in enumerate(path.read_text().splitlines(), 1) if line.startswith(text)), None)
