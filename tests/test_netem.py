"""Impairment models and the shim: measured loss rates and delay
distributions match each profile's declared model, draws are reproducible
per link, reliable messages are late but never lost, and the GPS error has
the published size and time correlation."""

import math

import numpy as np
import pytest
import shapely

from bearcat.bus import keys
from bearcat.netem.link import LinkState, Tcp
from bearcat.netem.models import (
    CompassError,
    CompassTrack,
    Delay,
    GilbertElliott,
    GpsError,
    GpsTrack,
    LinkModel,
    Outage,
)
from bearcat.netem.profiles import ProfileError, load_profile, load_profiles
from bearcat.netem.shim import Shim

FIX = keys.fix("g", "a1")
STATE = keys.state("g")
PAYLOAD = b"x" * 60


def stream(shim, n, key=FIX, period=0.1, sender="a1", receiver="gs", start=0.0):
    """``n`` messages at ``period``; (sent time, arrival times) each."""
    return [
        (start + k * period, [d.at for d in shim.transmit(sender, receiver, key, PAYLOAD, start + k * period)])
        for k in range(n)
    ]


# ---------------------------------------------------------------------- delay


@pytest.mark.parametrize("distribution", ["uniform", "normal", "pareto", "lognormal"])
def test_delay_jitter_has_the_declared_spread(distribution):
    rng = np.random.default_rng(1)
    d = Delay(base=0.5, jitter=0.05, distribution=distribution)
    x = np.array([d.sample(rng) for _ in range(40000)])
    spread = x.std()
    expected = 0.05 / math.sqrt(3) if distribution == "uniform" else 0.05
    assert spread == pytest.approx(expected, rel=0.1 if distribution != "pareto" else 0.25)
    if distribution in ("uniform", "normal"):
        assert x.mean() == pytest.approx(0.5, abs=0.002)
    else:  # one-sided heavy tails: never early
        assert x.min() >= 0.5


def test_a_delay_is_never_negative():
    rng = np.random.default_rng(0)
    d = Delay(base=0.01, jitter=0.05, distribution="normal")
    assert min(d.sample(rng) for _ in range(5000)) == 0.0


# ---------------------------------------------------------------------- loss


def test_bernoulli_loss_rate_is_measured_within_three_sigma():
    shim = Shim(LinkModel(loss=0.1), seed=3, transport="udp")
    arrivals = stream(shim, 20000)
    lost = np.mean([not a for _, a in arrivals])
    assert abs(lost - 0.1) < 3 * math.sqrt(0.1 * 0.9 / 20000)


def test_gilbert_elliott_loss_has_its_stationary_rate_and_burst_length():
    ge = GilbertElliott(p=0.02, r=0.2, loss_good=0.0, loss_bad=1.0)
    shim = Shim(LinkModel(burst=ge), seed=4, transport="udp")
    lost = np.array([not a for _, a in stream(shim, 100000)])
    assert lost.mean() == pytest.approx(ge.stationary_loss, rel=0.1)
    edges = np.flatnonzero(np.diff(np.r_[0, lost.astype(int), 0]))
    bursts = edges[1::2] - edges[::2]
    assert bursts.mean() == pytest.approx(1 / ge.r, rel=0.1)  # Bernoulli loss at the same rate gives ~1.1


def test_reliable_messages_are_never_lost_only_late_and_in_order():
    shim = Shim(LinkModel(delay=Delay(0.1, 0.05, "normal"), loss=0.3), seed=5)
    arrivals = stream(shim, 2000, key=STATE)
    assert all(len(a) == 1 for _, a in arrivals)
    times = [a[0] for _, a in arrivals]
    assert times == sorted(times)
    late = [a[0] - s for s, a in arrivals]
    assert max(late) > 0.4  # some needed a retransmission


def test_over_udp_duplicates_happen_at_their_rate_and_a_reordered_message_is_lost():
    """Zenoh drops a best-effort message older than one it delivered, so a
    message that would overtake the ones in flight costs one; the rest
    arrive in order, as a cellular bearer delivers them."""
    shim = Shim(LinkModel(delay=Delay(0.3, 0.01, "normal"), duplicate=0.05, reorder=0.1), seed=6, transport="udp")
    arrivals = stream(shim, 20000, period=0.01)
    assert np.mean([not a for _, a in arrivals]) == pytest.approx(0.1, abs=0.006)
    delivered = [a for _, a in arrivals if a]
    assert np.mean([len(a) == 2 for a in delivered]) == pytest.approx(0.05 * 0.9, abs=0.006)
    first = np.array([a[0] for a in delivered])
    assert (np.diff(first) >= 0).all()


# ---------------------------------------------------------------------- outages, dead zones, promotion


def test_an_outage_drops_fixes_and_holds_state_until_it_ends():
    shim = Shim(LinkModel(delay=Delay(0.1), outages=(Outage(1.0, 3.0),)), seed=7, transport="udp")
    assert shim.transmit("a1", "gs", FIX, PAYLOAD, 2.0) == []
    (held,) = shim.transmit("gs", "a1", STATE, PAYLOAD, 2.0)
    assert held.at == pytest.approx(3.1)
    assert shim.transmit("a1", "gs", FIX, PAYLOAD, 3.0)[0].at == pytest.approx(3.1)


def test_outage_windows_count_from_the_game_start_on_a_live_clock():
    """Live peers read Unix time; the windows are game time, from the start command."""
    model = LinkModel(delay=Delay(0.1), outages=(Outage(1.0, 3.0),))
    before_start = Shim(model, seed=7, epoch=None, transport="udp")
    assert before_start.transmit("a1", "gs", FIX, PAYLOAD, 1_700_000_002.0)  # no game yet, no window
    live = Shim(model, seed=7, epoch=1_700_000_000.0, transport="udp")
    assert live.transmit("a1", "gs", FIX, PAYLOAD, 1_700_000_002.0) == []
    (held,) = live.transmit("gs", "a1", STATE, PAYLOAD, 1_700_000_002.0)
    assert held.at == pytest.approx(1_700_000_003.1)
    assert live.transmit("a1", "gs", FIX, PAYLOAD, 1_700_000_004.0)


def test_a_dead_zone_cuts_a_phone_off_and_poll_releases_what_was_held():
    position = {"a1": (5.0, 5.0)}
    records = []
    shim = Shim(
        LinkModel(delay=Delay(0.1)),
        seed=8,
        dead_zones=shapely.box(0, 0, 10, 10),
        where=position.get,
        record=records.append,
        transport="udp",
    )
    assert shim.transmit("a1", "gs", FIX, PAYLOAD, 1.0) == []
    assert shim.transmit("gs", "a1", STATE, PAYLOAD, 1.0, token="state #1") == []
    assert shim.poll(2.0) == []
    position["a1"] = (20.0, 5.0)
    ((token, delivery),) = shim.poll(4.0)
    assert token == "state #1" and delivery.at == pytest.approx(4.1)
    assert [r.action for r in records] == ["dropped", "held", "delivered"]
    assert records[0].reasons == ("dead zone",) and records[2].delay == pytest.approx(3.1)


def test_the_first_message_after_the_radio_idled_waits_for_promotion():
    shim = Shim(LinkModel(delay=Delay(0.1), idle_after=5.0, promotion=(1.0, 2.6)), seed=9)
    first = shim.transmit("a1", "gs", FIX, PAYLOAD, 0.0)[0].at
    busy = shim.transmit("a1", "gs", FIX, PAYLOAD, 1.0)[0].at
    after_idle = shim.transmit("a1", "gs", FIX, PAYLOAD, 20.0)[0].at
    assert first == pytest.approx(0.1) and busy == pytest.approx(1.1)
    assert 1.0 <= after_idle - 20.1 <= 2.6


# ---------------------------------------------------------------------- seeding


def test_a_link_replays_for_a_seed_whatever_other_links_carry():
    model = load_profile("3g-degraded").link
    alone = Shim(model, seed=11)
    busy = Shim(model, seed=11)
    for k in range(500):
        busy.transmit("b1", "gs", keys.fix("g", "b1"), PAYLOAD, k * 0.05)
    assert stream(alone, 500) == stream(busy, 500)
    assert stream(Shim(model, seed=12), 500) != stream(Shim(model, seed=11), 500)


def test_truth_and_control_are_never_impaired():
    shim = Shim(LinkModel(loss=1.0, delay=Delay(1.0)), seed=1)
    for key in (keys.truth("g", "a1"), keys.control("g")):
        assert [d.at for d in shim.transmit("a1", "gs", key, PAYLOAD, 2.0)] == [2.0]


def test_every_impairment_is_recorded():
    records = []
    shim = Shim(load_profile("3g-degraded").link, seed=2, record=records.append, transport="udp")
    arrivals = stream(shim, 3000)
    delivered = sum(len(a) for _, a in arrivals)
    assert sum(r.action in ("delivered", "duplicated") for r in records) == delivered
    assert sum(r.action == "dropped" for r in records) == sum(not a for _, a in arrivals)
    assert {r.reasons[0] for r in records if r.action == "dropped"} <= {"loss", "burst", "reordered"}


# ---------------------------------------------------------------------- profiles


@pytest.mark.parametrize("name", ["ideal", "wifi", "3g", "3g-degraded"])
def test_each_profile_measures_as_declared(name):
    profile = load_profile(name)
    m = profile.link
    shim = Shim(m, seed=21, transport="udp")
    arrivals = stream(shim, 20000)
    delays = np.array([a[0] - s for s, a in arrivals if a])
    lost = np.mean([not a for _, a in arrivals])
    # Over udp/ a reordered datagram is lost too: Zenoh drops what arrives behind a newer one.
    expected_loss = 1 - (1 - m.loss) * (1 - (m.burst.stationary_loss if m.burst else 0.0)) * (1 - m.reorder)
    # Bursts make successive losses depend on each other: the Gilbert-Elliott
    # chain's state correlates with lag k as (1 - p - r)^k, which widens the
    # spread of a loss fraction by (1 + lambda) / (1 - lambda) over independent draws.
    correlation = 1 - m.burst.p - m.burst.r if m.burst else 0.0
    spread = math.sqrt(max(expected_loss, 1e-4) / 20000 * (1 + correlation) / (1 - correlation))
    assert abs(lost - expected_loss) < 4 * spread
    assert np.median(delays) >= m.delay.base - 1e-9
    if m.delay.jitter == 0:
        assert np.ptp(delays) == 0.0
    else:
        assert np.median(delays) < m.delay.base + 2 * m.delay.jitter


def test_3g_round_trip_matches_the_published_hspa_figure():
    m = load_profile("3g").link
    shim = Shim(m, seed=22)
    up = np.array([a[0] - s for s, a in stream(shim, 5000, sender="a1", receiver="gs") if a])
    down = np.array([a[0] - s for s, a in stream(shim, 5000, sender="gs", receiver="a1") if a])
    assert 0.2 < np.median(up) + np.median(down) < 0.3  # about 230 ms


def test_a_misspelt_profile_key_is_named_with_its_file(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text("[mine.link]\ndealy = 0.1\n")
    with pytest.raises(ProfileError, match=r"p.toml: mine.link: unknown key 'dealy'; the keys there are delay, jitter"):
        load_profiles(path)
    with pytest.raises(ProfileError, match="no netem profile 'lte'"):
        load_profile("lte")
    path.write_text("[mine.link]\nloss = 1.5\n")
    with pytest.raises(ProfileError, match="probability"):
        load_profiles(path)


@pytest.mark.parametrize(
    "text, culprit",
    [
        ("[mine.link]\nloss = 1.5\n", "mine.link.loss: must be a probability in [0, 1], got 1.5"),
        (
            "[mine.link]\nburst = { p = 0.1, r = -0.2 }\n",
            "mine.link.burst.r: must be a probability in [0, 1], got -0.2",
        ),
        ("[mine.link]\nburst = { p = 0.1 }\n", "mine.link.burst.r: must be given, as a probability in [0, 1]"),
        ("[mine.link]\ndelay = nan\n", "mine.link.delay: must be a number in [0, 60] s, got nan"),
        ("[mine.link]\njitter = -0.1\n", "mine.link.jitter: must be a number in [0, 60] s, got -0.1"),
        ("[mine.link]\nrate = inf\n", "mine.link.rate: must be a number in [0, 1e12] bytes/s, got inf"),
        (
            "[mine.link]\npromotion = [2.6, 1.0]\n",
            "mine.link.promotion: has its longest, 1 s, below its shortest, 2.6 s",
        ),
        ("[mine.link]\noutages = 5\n", "mine.link.outages: must be a list, got 5"),
        ("[mine.link]\noutages = [[5.0, 1.0]]\n", "mine.link.outages[0]: ends at 1 s, before it starts at 5 s"),
        ("[mine.link]\ndistribution = 'cauchy'\n", "mine.link.distribution: 'cauchy' is not one of 'constant',"),
        ("[mine.gps]\ntau = 0\n", "mine.gps.tau: must be a number in (0, 86400] s, got 0"),
        ("[mine.gps]\nurban_dropout = 2\n", "mine.gps.urban_dropout: must be a probability in [0, 1], got 2"),
        (
            "[mine.compass]\nnoise_sigma = -inf\n",
            "mine.compass.noise_sigma: must be a number in [0, 180] degrees, got -inf",
        ),
        ("mine = 5\n", "mine: must be a table, got 5"),
    ],
)
def test_every_number_of_a_profile_has_its_bounds(tmp_path, text, culprit):
    path = tmp_path / "p.toml"
    path.write_text(text)
    with pytest.raises(ProfileError) as error:
        load_profiles(path)
    assert str(error.value).startswith(f"{path}: {culprit}")


def test_a_profile_file_that_is_not_utf8_is_named(tmp_path):
    path = tmp_path / "p.toml"
    path.write_bytes("[caf\xe9]\n".encode("latin-1"))
    with pytest.raises(ProfileError, match=rf"^{path} is not UTF-8 text$"):
        load_profiles(path)


# ---------------------------------------------------------------------- sensors


def test_open_sky_gps_error_is_about_4_9_m_at_95_percent_and_correlated():
    model = load_profile("wifi").gps
    errors = []
    for seed in range(40):
        track = GpsTrack(model, np.random.default_rng(seed))
        errors.append([track.error(t) for t in np.arange(0.0, 600.0, 1.0)])
    e = np.array(errors)  # (runs, fixes, 2)
    radial = np.hypot(e[..., 0], e[..., 1])
    assert np.percentile(radial, 95) == pytest.approx(4.9, rel=0.15)
    x = e[..., 0]
    lag = int(model.tau)
    corr = np.mean(x[:, :-lag] * x[:, lag:]) / np.mean(x * x)
    bias_share = model.bias_sigma**2 / (model.bias_sigma**2 + model.noise_sigma**2)
    assert corr == pytest.approx(bias_share * math.exp(-1.0), abs=0.08)


def test_gps_near_buildings_is_worse_and_drops_out_more():
    model = load_profile("3g").gps
    open_sky = GpsTrack(model, np.random.default_rng(1))
    urban = GpsTrack(model, np.random.default_rng(1))
    far = [open_sky.error(t, 100.0) for t in range(3000)]
    near = [urban.error(t, 5.0) for t in range(3000)]
    assert np.mean([e is None for e in near]) == pytest.approx(model.urban_dropout, abs=0.015)
    mean_far = np.mean([np.hypot(*e) for e in far if e is not None])
    mean_near = np.mean([np.hypot(*e) for e in near if e is not None])
    assert 7.0 <= mean_near <= 13.0 and mean_near / mean_far == pytest.approx(model.urban_factor, rel=0.2)


def test_the_compass_keeps_its_bias():
    track = CompassTrack(CompassError(bias_sigma=5.0, noise_sigma=1.0), np.random.default_rng(3))
    readings = np.array([track.reading(0.5) for _ in range(4000)])
    offset = (readings - 0.5 + math.pi) % (2 * math.pi) - math.pi
    assert offset.mean() == pytest.approx(track.bias, abs=0.002)
    assert offset.std() == pytest.approx(math.radians(1.0), rel=0.1)


def test_a_perfect_gps_has_no_error():
    track = GpsTrack(GpsError(), np.random.default_rng(0))
    assert np.all(track.error(0.0) == 0) and np.all(track.error(5.0) == 0)


# ---------------------------------------------------------------------- the TCP stream


def tcp_stream(model, n=6000, period=0.1, seed=31):
    """``n`` fixes ``period`` apart through a link over tcp/: (sent, arrival, reasons) each."""
    records = []
    shim = Shim(model, seed=seed, record=records.append, transport="tcp")
    for k in range(n):
        shim.transmit("a1", "gs", FIX, PAYLOAD, k * period)
    return [(r.sent, r.sent + r.delay, r.reasons) for r in records]


def test_over_tcp_a_lost_packet_stalls_for_the_recovery_its_model_declares():
    model = LinkModel(delay=Delay(0.1), loss=0.02)
    messages = tcp_stream(model)
    tcp = Tcp.of(model)
    assert tcp.srtt == pytest.approx(0.2) and tcp.rto == pytest.approx(Tcp.MIN_RTO)
    once = [at - sent - 0.1 for sent, at, why in messages[100:] if why == ("retransmitted x1",)]
    twice = [at - sent - 0.1 for sent, at, why in messages[100:] if why == ("retransmitted x2",)]
    assert len(once) > 50 and twice
    # RACK: the next fix 0.1 s later is acknowledged a round trip on, plus a quarter of one.
    assert np.median(once) == pytest.approx(0.1 + 1.25 * 0.2, abs=0.01)
    # Lost again: the retransmission timer, on top.
    assert np.median(twice) == pytest.approx(0.1 + 1.25 * 0.2 + Tcp.MIN_RTO, abs=0.01)


def test_over_tcp_nothing_is_lost_and_what_follows_a_loss_arrives_with_it_in_a_burst():
    messages = tcp_stream(LinkModel(delay=Delay(0.1), loss=0.02))
    arrivals = np.array([at for _, at, _ in messages])
    assert len(messages) == 6000 and (np.diff(arrivals) >= 0).all()  # every fix, in order
    stalls = [k for k, (_, _, why) in enumerate(messages) if why == ("retransmitted x1",)]
    for k in stalls[:20]:
        held = [j for j in range(k + 1, len(messages)) if messages[j][0] + 0.1 < arrivals[k]]
        assert held, "a 0.35 s stall holds the fixes sent behind it"
        assert all(arrivals[j] == arrivals[k] for j in held)  # released together with the lost one


def test_after_a_timeout_slow_start_lets_one_packet_go_in_the_first_round_trip_then_two_then_four():
    state = LinkState(LinkModel(delay=Delay(0.5)), np.random.default_rng(0))
    for k in range(20):  # a steady stream 0.1 s apart: the smoothed gap settles near 0.1
        state.carry(k * 0.1, 100, way="stream")
    state.slow_start, state.sent_since = 2.0, 0  # as after a retransmission timeout at 2 s
    departures = [state.carry(2.0 + k * 0.01, 100, way="stream").copies[0].at - 0.5 for k in range(7)]
    rounds = [round((d - 2.0) / state.tcp.srtt) for d in departures]
    assert rounds == [0, 1, 1, 2, 2, 2, 2]


def test_an_ip_packet_draws_its_loss_once_and_a_message_once_per_segment():
    """The kernel hub sees IP packets up to the MTU (1500 bytes with their
    headers): each is one draw. A 3000-byte message needs three segments,
    and over a datagram link it is lost if any of them is."""
    n = 4000

    def lost(way, size):
        link = LinkState(LinkModel(loss=0.3), np.random.default_rng(5))
        return np.mean([link.carry(0.1 * k, size, way=way).lost is not None for k in range(n)])

    spread = 4 * math.sqrt(0.25 / n)
    assert abs(lost("packet", 1500) - 0.3) < spread
    assert abs(lost("datagram", 3000) - (1 - 0.7**3)) < spread
