"""Supervision: a live run starts again the peers that die when no fault
plan asked for it, as its scenario's ``[supervision]`` says, and gives up
on one that dies too often. The policy's arithmetic here; the ground
station and a UAV killed from outside live runs in ``test_crashes``."""

from __future__ import annotations

import pytest

from bearcat.runtime.supervisor import Supervisor
from bearcat.scenarios.schema import ScenarioError, load_scenario, parse_scenario
from bearcat.scenarios.supervision import Restarts, Supervision
from tests.support.scenario_files import write_scenario


def test_a_death_is_restarted_after_a_backoff_that_doubles_within_the_period():
    supervisor = Supervisor(Supervision(max_restarts=5, period=60.0, backoff=0.5, backoff_max=3.0))
    waits = [supervisor.died("gs", "ground-station", -9, t).wait for t in (0.0, 10.0, 20.0, 30.0, 40.0)]
    assert waits == [0.5, 1.0, 2.0, 3.0, 3.0]  # 0.5 * 2**k, held at backoff_max


def test_restarts_older_than_the_period_are_forgotten():
    supervisor = Supervisor(Supervision(max_restarts=2, period=10.0, backoff=1.0))
    first = [supervisor.died("gs", "ground-station", 1, t) for t in (0.0, 5.0)]
    later = supervisor.died("gs", "ground-station", 1, 12.0)  # the death at 0 is out of the window, 5 in it
    assert [d.restart for d in first] == [True, True] and later.restart and later.wait == 2.0


def test_one_death_past_the_intensity_gives_the_peer_up_saying_so():
    supervisor = Supervisor(Supervision(max_restarts=3, period=60.0))
    deaths = [supervisor.died("q1", "uav", -9, float(t)) for t in range(4)]
    assert [d.restart for d in deaths] == [True, True, True, False]
    assert deaths[-1].gives_up
    assert deaths[-1].why == (
        "peer q1 restarted too often: 4 unplanned deaths within 60 s (max_restarts 3), the last with code -9"
    )


def test_each_peer_has_its_own_intensity():
    supervisor = Supervisor(Supervision(max_restarts=1))
    assert supervisor.died("q1", "uav", -9, 0.0).restart
    assert supervisor.died("q2", "uav", -9, 0.0).restart
    assert supervisor.died("q1", "uav", -9, 1.0).gives_up


def test_a_clean_exit_and_a_never_role_are_not_restarted():
    supervisor = Supervisor(Supervision())
    clean = supervisor.died("gs", "ground-station", 0, 0.0)
    walker = supervisor.died("attacker", "walker", -9, 0.0)
    vehicle = supervisor.died("vehicle-q1", None, -9, 0.0)
    assert not any(d.restart or d.gives_up for d in (clean, walker, vehicle))
    assert clean.why == "it exited as asked (code 0)" and walker.why == "walkers are not restarted"


def test_max_restarts_zero_gives_up_at_the_first_death():
    death = Supervisor(Supervision(max_restarts=0)).died("gs", "ground-station", -9, 0.0)
    assert death.gives_up and not death.restart


def test_the_defaults_restart_the_ground_station_and_uavs_but_not_players():
    scenario = load_scenario("search")
    assert scenario.supervision == Supervision()
    restart = scenario.supervision.restart
    assert [restart.of(r) for r in ("ground-station", "uav", "walker", "phone")] == [
        "on-failure",
        "on-failure",
        "never",
        "never",
    ]


def test_a_scenario_sets_its_supervision_per_role(tmp_path):
    path = write_scenario(tmp_path)
    text = path.read_text() + (
        '\n[supervision]\nmax_restarts = 1\nperiod = 5.0\nbackoff = 0.2\nrestart = { walker = "on-failure" }\n'
    )
    scenario = parse_scenario(text, source="mine.toml")
    assert scenario.supervision == Supervision(
        restart=Restarts(walker="on-failure"), max_restarts=1, period=5.0, backoff=0.2
    )


@pytest.mark.parametrize(
    ("table", "said"),
    [
        ('restart = { ground_station = "never" }', "supervision.restart"),
        ('restart = { walker = "always" }', "supervision.restart.walker"),
        ("max_restarts = -1", "supervision.max_restarts"),
        ("period = 0.0", "supervision.period"),
        ("retries = 3", "supervision"),
    ],
)
def test_a_wrong_supervision_key_is_one_sentence_naming_it(tmp_path, table, said):
    text = write_scenario(tmp_path).read_text() + f"\n[supervision]\n{table}\n"
    with pytest.raises(ScenarioError) as error:
        parse_scenario(text, source="mine.toml")
    message = str(error.value)
    assert message.startswith(f"mine.toml: {said}") and "\n" not in message, message
